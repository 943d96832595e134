"""The Jazzy ``main`` of every node of the suite, written once, and the nodes' ``--help``.

``run_node`` answers ``-h``/``--help`` (among the arguments before ``--ros-args``) with the
node's usage, generated from its module docstring and its parameter tables, without starting
anything: no ``rclpy.init``, no file written. A configuration error (a missing or invalid
parameter) ends the node with one line on stderr and exit status 1, no traceback; so does a
``--params-file`` that is missing, unreadable or not a params file (:func:`params_file_problem`,
checked before ``rclpy.init``, which would otherwise end in a traceback), and a ``-p`` override that rcl
would drop without a word because the params file gives the parameter another type (:func:`override_problem`).

Stops (:class:`StopSignals`): SIGINT (Ctrl-C) and SIGTERM (``kill``, a supervisor, or the parent-death signal
of a node started by a script, ros/launching.py) are the same clean stop. The first one asks the node to stop:
a node being made is finished first, then the spin ends, the node's ``close()`` runs while its context is still
valid (a proxy can still cancel its running goal at the controller, a recorder finishes its bag), the node is
destroyed (its executor threads joined) and the process exits with status 0. A second SIGINT (Ctrl-C twice)
stops at once (``KeyboardInterrupt``); more SIGTERMs change nothing (the parent-death signal may come once per
thread of a parent killed with ``kill -9``; SIGKILL is the way to end a stop that hangs). rclpy's own signal
handlers are not installed: they shut the context down first, so ``close()`` could no longer talk to the graph,
and their ``KeyboardInterrupt`` could land inside a node's constructor after it had started an executor thread,
which then outlived the interpreter and aborted the process at exit ("terminate called without an active
exception", ros2/rclpy#1484).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import sys
import textwrap
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from shaper_nodes.core.closed_pipe import quiet_closed_pipe

#: what ``run_node`` returns when the node's configuration is refused
EXIT_CONFIG = 1
#: width of the --help text
WIDTH = 100


#: the signals that stop a node cleanly
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """SIGINT and SIGTERM as a request to stop, acted on between callbacks (see the module docstring).

    From the main thread only (Python runs signal handlers there); elsewhere it installs nothing. The
    first signal sets :attr:`signal` and wakes the executor through a guard condition (:meth:`wake_with`):
    Python's own handler runs only when the main thread returns from rcl's wait, so a thread reading the
    signal wake-up pipe (``signal.set_wakeup_fd``) triggers it. A second SIGINT raises ``KeyboardInterrupt``;
    a repeated SIGTERM is ignored (see the module docstring).
    """

    def __init__(self) -> None:
        #: the first stop signal received (None: none yet)
        self.signal: int | None = None
        self.interrupts = 0  # SIGINTs received
        self._wake: Callable[[], None] | None = None
        self._installed = threading.current_thread() is threading.main_thread()
        if not self._installed:
            return
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        self._old_handlers = {sig: signal.signal(sig, self._on_signal) for sig in STOP_SIGNALS}
        self._old_fd = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        self._closed = False
        self._thread = threading.Thread(target=self._watch, name="stop signals", daemon=True)
        self._thread.start()

    def _on_signal(self, signum: int, frame: object) -> None:
        if signum == signal.SIGINT:
            self.interrupts += 1
            if self.interrupts > 1:
                raise KeyboardInterrupt
        if self.signal is None:
            self.signal = signum

    def _watch(self) -> None:
        while os.read(self._read, 64) and not self._closed:
            wake = self._wake
            if wake is not None:
                with contextlib.suppress(Exception):  # the node is being destroyed: the stop is under way
                    wake()

    def wake_with(self, node: Any) -> None:
        """Wake ``node``'s executor on a signal: a guard condition of the node, triggered by the watch thread."""
        if self._installed:
            self._wake = node.create_guard_condition(lambda: None).trigger

    def close(self) -> None:
        """Restore the previous handlers and stop the watch thread."""
        if not self._installed or self._closed:
            return
        self._closed = True
        self._wake = None
        signal.set_wakeup_fd(self._old_fd)
        for sig, handler in self._old_handlers.items():
            signal.signal(sig, handler)
        os.write(self._write, b"\0")
        self._thread.join(1.0)
        os.close(self._write)
        os.close(self._read)


def with_config(package: str, executable: str, config: str, extra: str = "") -> str:
    """A ``ros2 run`` line that starts ``executable`` with the package's shipped config file ``config``."""
    return (f"ros2 run {package} {executable} --ros-args --params-file"
            f" $(ros2 pkg prefix {package})/share/{package}/config/{config}{' ' + extra if extra else ''}")


def wants_help(argv: Sequence[str]) -> bool:
    """Whether ``-h`` or ``--help`` is among the arguments before ``--ros-args`` (``argv[0]`` is the
    program); what follows ``--ros-args`` is ROS's."""
    args = list(argv[1:])
    if "--ros-args" in args:
        args = args[:args.index("--ros-args")]
    return "-h" in args or "--help" in args


def params_files(argv: Sequence[str]) -> list[str]:
    """The files given with ``--params-file FILE`` among the ROS arguments of ``argv`` (after
    ``--ros-args``, up to ``--`` or the end)."""
    files: list[str] = []
    inside = False
    args = list(argv)
    for i, arg in enumerate(args):
        if arg == "--ros-args":
            inside = True
        elif arg == "--":
            inside = False
        elif inside and arg == "--params-file" and i + 1 < len(args):
            files.append(args[i + 1])
    return files


def params_file_problem(argv: Sequence[str]) -> str | None:
    """Why a ``--params-file`` of ``argv`` cannot be used, in one line naming the file (None if
    every one can be): missing, unreadable, not YAML, or not a params file (a mapping of node
    names, ``/**`` or ``/name``, each to a mapping with ``ros__parameters``). rcl reads the file
    again at ``rclpy.init``; these are the problems it would otherwise report as a traceback. Then a
    ``-p`` override rcl would drop (:func:`override_problem`)."""
    import yaml

    for path in params_files(argv):
        try:
            with open(path, encoding="utf-8") as f:
                tree = yaml.safe_load(f)
        except FileNotFoundError:
            return f"--params-file {path}: no such file"
        except (OSError, UnicodeDecodeError) as err:
            return f"--params-file {path}: cannot read it ({getattr(err, 'strerror', None) or err})"
        except yaml.YAMLError as err:
            mark = getattr(err, "problem_mark", None)
            where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
            problem = getattr(err, "problem", None) or str(err).splitlines()[0]
            return f"--params-file {path}: not valid YAML{where}: {problem}"
        if not isinstance(tree, dict) or not tree:
            return f"--params-file {path}: not a params file (expected '<node name or /**>: ros__parameters: ...')"
        for key, body in tree.items():
            if not isinstance(body, dict) or "ros__parameters" not in body:
                return (f"--params-file {path}: key {key!r} has no 'ros__parameters' mapping"
                        " (expected '<node name or /**>: ros__parameters: ...')")
    return override_problem(argv)


#: the order in which rclpy reads a parameter's value out of rcl's variant (bool first, string arrays last)
_RCL_ORDER = ("a bool", "an integer", "a double", "a string", "a bool array", "an integer array", "a double array",
              "a string array")


def _rcl_kind(value: Any) -> int | None:
    """The index in :data:`_RCL_ORDER` of a YAML value as rcl stores it (None: nothing rcl would keep)."""
    if isinstance(value, list):
        kind = _rcl_kind(value[0]) if value else None
        return None if kind is None or kind > 3 else kind + 4
    for k, t in enumerate((bool, int, float, str)):
        if isinstance(value, t):
            return k
    return None


def _flat(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        out.update(_flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}": value})
    return out


def override_problem(argv: Sequence[str]) -> str | None:
    """A value of ``argv`` that rcl would drop without a word (None if none would be): a ``-p NAME:=VALUE``,
    or a later ``--params-file``'s value, of another type than an earlier value of NAME in the same entry.

    rcl keeps the earlier value beside the later one of another type, and rclpy reads the first it finds
    in :data:`_RCL_ORDER`: after ``--params-file`` with ``command_rate: 500`` (an integer), ``-p
    command_rate:=250.0`` (or a second file's ``250.0``) left the node at 500 Hz, and ``-p
    shaper.frequency_hz:=ten`` kept the file's 8 Hz (session 15's owner's walk; the node's own type
    checks never saw the later value). Such a value is refused here, naming both. rcl applies every
    params file, in order, then the ``-p`` rules; types mix within one entry of its table only (one key).
    """
    import yaml

    # (what gave it, its entry in rcl's table, the parameter's name, its value): files first, then -p rules. rcl
    # mixes two types within one entry only (a params file's key as written; "/**" for a -p rule without a node):
    # a "/**" value and a "/shaper" one are two entries, and rclpy applies the node's own after "/**"
    sources: list[tuple[str, str, str, Any]] = []
    for path in params_files(argv):
        with open(path, encoding="utf-8") as f:
            tree = yaml.safe_load(f)
        for key, body in tree.items():
            sources += [(f"--params-file {path} ({key})", str(key), name, value)
                        for name, value in _flat(body["ros__parameters"] or {}).items()]
    inside = False
    for i, arg in enumerate(argv):
        if arg == "--ros-args":
            inside = True
        elif arg == "--":
            inside = False
        elif inside and arg in ("-p", "--param") and i + 1 < len(argv) and ":=" in argv[i + 1]:
            left, _, text = argv[i + 1].partition(":=")
            node, _, name = left.rpartition(":")
            try:
                sources.append((f"-p {argv[i + 1]}", node or "/**", name, yaml.safe_load(text)))
            except yaml.YAMLError:
                continue  # rcl reports it
    for k, (where, scope, name, value) in enumerate(sources):
        given = _rcl_kind(value)
        for before, other, same, kept_value in sources[:k]:
            kept = _rcl_kind(kept_value)
            if same != name or scope != other or given is None or kept is None or kept >= given:
                continue
            if where.startswith("-p "):
                return (f"{where}: {_RCL_ORDER[given]}, where {before} gives {name} {_RCL_ORDER[kept]}"
                        f" ({kept_value!r}); rcl would keep that value and drop the override without a word:"
                        f" give {name} {_RCL_ORDER[kept]} on the command line, or change the file")
            return (f"{where}: {name} is {_RCL_ORDER[given]} ({value!r}), where {before} before it gives"
                    f" {_RCL_ORDER[kept]} ({kept_value!r}); rcl would keep the earlier value and drop this one"
                    f" without a word: give {name} one type in both ({_RCL_ORDER[kept]} or {_RCL_ORDER[given]})")
    return None


def params_file_keys_hint(argv: Sequence[str]) -> str:
    """For a node that refused its configuration: when every ``--params-file`` of ``argv`` is keyed by node
    names only (no ``*``), none of them the name the node is given with ``-r __node:=NAME`` (or no such
    remapping), a phrase saying whose parameters the files hold ("" otherwise). ``ros2 param dump /left_arm
    > dump.yaml`` writes ``/left_arm:``, which a node started from it under its default name does not take:
    it then refused a required parameter that the file does hold."""
    import yaml

    keys: list[str] = []
    for path in params_files(argv):
        try:
            with open(path, encoding="utf-8") as f:
                tree = yaml.safe_load(f)
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            return ""
        if not isinstance(tree, dict):
            return ""
        keys += [str(k) for k in tree]
    if not keys or any("*" in k for k in keys):
        return ""
    given = [a.split("__node:=", 1)[1] for a in argv if "__node:=" in a]
    if given and any(k.rsplit("/", 1)[-1] == given[-1] for k in keys):
        return ""
    first = keys[0].rsplit("/", 1)[-1]
    return (f" (note: the --params-file holds parameters for {', '.join(keys)} only; a node of another name takes"
            f" none of them: start it with -r __node:={first}, or key the file '/**:')")


def yaml_value(value: Any) -> str:
    """A parameter value as a params file or ``-p name:=value`` writes it."""
    if isinstance(value, str):
        return value if value and re.fullmatch(r"[A-Za-z_/~][\w/~.\-]*", value) else json.dumps(value)
    if isinstance(value, float):
        return repr(value) if value == value and abs(value) != float("inf") else (
            ".nan" if value != value else ("-.inf" if value < 0 else ".inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(yaml_value(v) for v in value) + "]"
    return json.dumps(value)


def parameter_help(tables: Mapping[str, Iterable[Any]]) -> str:
    """The parameters of ``tables`` (heading -> tuple of :class:`~shaper_nodes.ros.parameters.Spec`):
    name, type, default, range or choices, read-only, and description, one entry each."""
    from shaper_nodes.ros.parameters import TYPE_NAMES

    out: list[str] = []
    for heading, table in tables.items():
        out.append(f"Parameters{' (' + heading + ')' if heading else ''}:")
        for spec in table:
            facts = [TYPE_NAMES[spec.param_type],
                     "default " + ("[] (empty: not set)" if spec.default is None else yaml_value(spec.default))]
            if spec.range is not None:
                lo, hi = spec.range
                facts.append(f"range [{lo:g}, {hi:g}]")
            if spec.read_only:
                facts.append("read-only")
            out.append(f"  {spec.name} ({', '.join(facts)})")
            text = spec.description + (" One of: " + ", ".join(spec.choices) + "." if spec.choices else "")
            out.extend(textwrap.wrap(text, WIDTH, initial_indent=" " * 6, subsequent_indent=" " * 6))
        out.append("")
    return "\n".join(out)


def node_help(module: Any, executable: str, tables: Mapping[str, Iterable[Any]],
              examples: Sequence[str] = ()) -> str:
    """The ``--help`` text of node ``executable`` defined in ``module``."""
    package = module.__name__.split(".")[0]
    first = next(iter(next(iter(tables.values()), ())), None)
    doc = (module.__doc__ or "").strip().replace("``", "")
    specs = [s for table in tables.values() for s in table]
    # once each (modes may share a group of topics)
    topics = list({s.name: s for s in specs if s.name.startswith("topics.") or s.name == "topics"}.values())
    lines = [f"usage: ros2 run {package} {executable} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE]...",
             "                                [-r FROM:=TO]... [-r __node:=NAME] [-r __ns:=NAMESPACE]]", "",
             doc, ""]
    if topics:
        lines.append("Topics (the parameters naming them; or remap with -r FROM:=TO):")
        lines += [f"  {s.name} = {yaml_value(s.default)}" for s in topics]
        lines.append("")
    lines.append(parameter_help(tables))
    lines.append("A params file keyed '/**:' (as the shipped config files are) applies whatever the node is")
    lines.append("named; numbers may be written as integers where a double is declared (5 is 5.0).")
    lines.append("")
    lines.append("Examples:")
    examples = list(examples) or [f"ros2 run {package} {executable} --ros-args --params-file my_{executable}.yaml"]
    if first is not None and first.default is not None:
        examples.append(f"ros2 run {package} {executable} --ros-args -p {first.name}:={yaml_value(first.default)!s}"
                        f" -r __node:=my_{executable}")
    lines += [f"  {e}" for e in examples]
    return "\n".join(lines) + "\n"


def run_node(factory: Callable[[], Any], name: str, args: list[str] | None = None, *,
             tables: Mapping[str, Iterable[Any]] | None = None, examples: Sequence[str] = ()) -> int:
    """init, spin until SIGINT (Ctrl-C), SIGTERM or shutdown, then close, destroy and shut down (exit status 0).

    With ``-h``/``--help`` before ``--ros-args``, print the node's usage (its module docstring,
    ``tables`` or the module's ``PARAMETERS``, ``examples``) and return 0 without starting it.

    A configuration error (``ValueError`` or ``OSError`` such as ``FileExistsError`` from the
    constructor, or a parameter rclpy refuses) is printed on stderr as ``name: message`` and gives
    exit code 1, as does a ``--params-file`` that cannot be used (:func:`params_file_problem`). A
    node with a ``close()`` method gets it called before it is destroyed, with its context still valid
    when a signal stopped it (:class:`StopSignals`). A node that sets ``exit_code`` (and ``exit_reason``)
    ends with that code, the reason printed as ``name: reason``. With ``use_sim_time`` the node's ``/clock`` is
    taken on a side node's thread, not by its executor (:class:`~.sim_clock.ClockOnSide`).
    """
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        module = sys.modules[factory.__module__]
        text = node_help(module, name, tables or {"": getattr(module, "PARAMETERS", ())}, examples)
        return quiet_closed_pipe(lambda: print(text, end="", flush=True) or 0)

    problem = params_file_problem(argv)
    if problem is not None:
        print(f"{name}: {problem}", file=sys.stderr, flush=True)
        return EXIT_CONFIG
    stop = StopSignals()  # from here on SIGINT and SIGTERM ask for a clean stop
    try:
        return _run(factory, name, argv, stop)
    except KeyboardInterrupt:  # a second Ctrl-C: stopped at once
        return 0
    finally:
        stop.close()


def _run(factory: Callable[[], Any], name: str, argv: list[str], stop: StopSignals) -> int:
    """:func:`run_node` after the arguments were checked: init, make, spin until ``stop``, close, destroy."""
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # rcl's own refusal of the arguments (e.g. a params file it cannot parse)
        said = str(err).strip().splitlines()
        print(f"{name}: the ROS arguments were refused: {said[0] if said else type(err).__name__}",
              file=sys.stderr, flush=True)
        return EXIT_CONFIG
    from .sim_clock import ClockOnSide

    node = None
    clock: ClockOnSide | None = None
    executor = SingleThreadedExecutor()
    try:
        node = factory()  # a signal meanwhile is acted on once the node is made
        clock = ClockOnSide(node)  # /clock, with use_sim_time, on a thread of its own (ros/sim_clock.py)
        executor.add_node(node)
        stop.wake_with(node)
        while stop.signal is None and rclpy.ok():
            executor.spin_once()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, OSError, ParameterException) as err:
        message = " ".join(str(err).split()) + params_file_keys_hint(argv)
        print(f"{name}: {message}", file=sys.stderr, flush=True)
        return EXIT_CONFIG
    except Exception:
        if not rclpy.ok():  # the context was shut down while the node was being made: a stop
            return 0
        raise
    finally:
        executor.shutdown()
        if node is not None:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            if clock is not None:
                clock.close()
            node.destroy_node()
        rclpy.try_shutdown()
    code = int(getattr(node, "exit_code", 0) or 0)
    if code:
        print(f"{name}: {getattr(node, 'exit_reason', '') or 'failed'}", file=sys.stderr, flush=True)
    return code
