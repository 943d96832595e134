"""A fleet's recordings analysed in parallel, each result cached by the recording's content.

:func:`find_recordings` walks a folder for recordings: a rosbag2 folder (``metadata.yaml`` or
``.mcap`` files inside; not descended into further) or a bare ``.mcap`` file; hidden folders
(the cache among them) are skipped. :func:`content_key` hashes a recording: SHA-256 over its
files' names and bytes (streamed, 1 MiB at a time), the analysis options and
:data:`ANALYSIS_VERSION`, so that a changed recording, other options or a new analysis give another
key. Every recording is read through :mod:`shaper_nodes.recordings` with the bounds ``analyze_bag``
has (:class:`~shaper_nodes.recordings.ReadLimits`: metadata.yaml's size, chunk sizes and ratios), its
metadata.yaml too (the robot's name). :func:`analyze_one` is the task a worker runs: read, analyse
(no learner replays), and keep
the few numbers a fleet report needs (:class:`Result`, small JSON): the robot, the start time,
the modes with their uncertainties, the recommended shaper. A recording that cannot be analysed
gives a result with its ``error`` (reported per recording, never fatal to the fleet).

:func:`run_fleet` looks every key up in the cache folder and analyses the others, serially in
this process (``workers=0``) or on a Dask cluster (a local one of worker processes with one
thread each, or an existing one by its scheduler address), with an optional progress bar.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import pathlib
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from shaper_nodes.recordings import BagError, ReadLimits, read_metadata

from .analyze import Options
from .report import json_ready

#: part of every cache key: change it when the analysis or the result's fields change
ANALYSIS_VERSION = "fleet 2 (analyze 2026-11, issue 32: ringing modes first, plant changes)"
#: default refusal limit on the number of recordings under one folder
MAX_RECORDINGS = 5000
#: bytes read at a time when hashing
CHUNK = 1 << 20
#: one BLAS thread per worker process: the analysis' matrices are small, and several BLAS threads in each of
#: several processes on few cores spin against each other (the calibration measured 2.5x slower on 2 cores)
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: metadata.yaml custom_data key (rosbag2 format >= 6) naming the robot that made the recording
ROBOT_KEY = "robot"


class FleetError(ValueError):
    """The fleet cannot be analysed as asked (nothing there, too many recordings, bad cache folder)."""


@dataclass
class Result:
    """What a fleet report keeps of one recording's analysis (all plain data, JSON-ready).

    Attributes
    ----------
    path : str
        The recording (as given to the analysis).
    key : str
        Its content key (:func:`content_key`), hex.
    robot : str
        The robot: ``robot`` in the rosbag2 metadata's custom_data, else the parent folder's name.
    start_s : float
        The first accelerometer sample, s since the epoch (NaN if unknown).
    modes : list of dict
        ``frequency_hz``, ``frequency_std_hz``, ``zeta``, ``zeta_std``, ``amplitude``, ``method``, ``rings``
        (used for the shaper, as analyze_bag decides); those that ring first, strongest first.
    headline : list of str
        analyze_bag's headline: where the cycles' modes change (a payload, tool or pose change).
    groups : list of list of float
        The ringing modes (Hz, ascending) of each group of cycles, in the order of their first cycle.
    recommendation : dict or None
        ``family``, ``duration_s``, ``v_nominal``, ``v_worst`` of the recommended shaper.
    cycles : int
        Cycles found.
    error : str
        Why the recording could not be analysed ("" if it was).
    damage : list of str
        What a damaged recording lost, described.
    seconds : float
        Analysis time, s (0 for a cache hit as read back).
    """

    path: str
    key: str
    robot: str
    start_s: float = float("nan")
    modes: list[dict[str, Any]] = field(default_factory=list)
    recommendation: dict[str, Any] | None = None
    headline: list[str] = field(default_factory=list)
    groups: list[list[float]] = field(default_factory=list)
    cycles: int = 0
    error: str = ""
    damage: list[str] = field(default_factory=list)
    seconds: float = 0.0
    version: str = ANALYSIS_VERSION

    def to_json(self) -> dict[str, Any]:
        """Strict-JSON form (NaN as None)."""
        return json_ready(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> Result:
        """The inverse of :meth:`to_json`."""
        names = {f.name for f in dataclasses.fields(cls)}
        out = cls(**{k: v for k, v in doc.items() if k in names})
        if out.start_s is None:
            out.start_s = float("nan")
        return out


# ------------------------------------------------------------------------------ finding and hashing
def _is_rosbag2(folder: pathlib.Path) -> bool:
    return (folder / "metadata.yaml").is_file() or any(p.suffix == ".mcap" for p in folder.iterdir() if p.is_file())


def find_recordings(root: str | pathlib.Path, limit: int = MAX_RECORDINGS) -> list[pathlib.Path]:
    """Every recording under ``root`` (rosbag2 folders and bare .mcap files), sorted by path.

    Raises
    ------
    FleetError
        ``root`` is not a folder, or holds more than ``limit`` recordings (refused before any work).
    """
    root = pathlib.Path(root)
    if not root.exists():
        raise FleetError(f"{root}: no such folder")
    if not root.is_dir():
        raise FleetError(f"{root}: not a folder" + ("; it is one recording: analyze_bag analyses one recording"
                                                    if root.suffix == ".mcap" else ""))
    found: list[pathlib.Path] = []
    for here, dirs, files in os.walk(root):
        folder = pathlib.Path(here)
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        if (folder != root and _is_rosbag2(folder)) or (folder == root and (folder / "metadata.yaml").is_file()):
            found.append(folder)
            dirs[:] = []
        else:
            found += [folder / f for f in sorted(files) if f.endswith(".mcap") and not f.startswith(".")]
        if len(found) > limit:
            raise FleetError(f"{root}: more than {limit} recordings (--max-recordings); refused before analysing any")
    return sorted(found)


def recording_files(path: pathlib.Path) -> list[pathlib.Path]:
    """The files of a recording: the file itself, or the folder's files (not in subfolders), sorted."""
    if path.is_file():
        return [path]
    return sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))


def content_key(path: pathlib.Path, options: Options, limits: ReadLimits | None = None) -> str:
    """SHA-256 (hex) of the recording's file names and bytes (streamed), the options and the version
    (and the reading limits when they are not the defaults: a recording refused under some limits is
    read again under others).

    Raises
    ------
    OSError
        A file cannot be read.
    """
    h = hashlib.sha256()
    h.update(ANALYSIS_VERSION.encode())
    h.update(json.dumps(options_doc(options), sort_keys=True).encode())
    if limits is not None and limits != ReadLimits():
        h.update(json.dumps(dataclasses.asdict(limits), sort_keys=True).encode())
    for f in recording_files(path):
        h.update(f"\0{f.name}\0{f.stat().st_size}\0".encode())
        with f.open("rb") as fh:
            while chunk := fh.read(CHUNK):
                h.update(chunk)
    return h.hexdigest()


def options_doc(options: Options) -> dict[str, Any]:
    """The options as plain data (part of the cache key)."""
    doc = dataclasses.asdict(options)
    doc["learner_params"] = dict(options.learner_params)
    return json_ready(doc)


def robot_of(path: pathlib.Path, limits: ReadLimits | None = None, root: pathlib.Path | None = None) -> str:
    """The robot that made a recording: ``robot`` of the rosbag2 metadata's custom_data, else the name of
    the folder holding the recording (``fleet/cell_3/rec_012``: ``cell_3``), except that a recording
    directly in the fleet's folder ``root`` (no robot folder) is a robot of its own, named by the
    recording (``bags/arm_production_payload``: ``arm_production_payload``), not one robot with every
    other loose recording there.

    metadata.yaml is read through :func:`shaper_nodes.recordings.read_metadata` (its size checked
    against ``limits.metadata_bytes`` before it is parsed); one beyond the limit, or unreadable, gives
    the folder's name (the analysis then refuses the recording with the reason).
    """
    meta = path / "metadata.yaml" if path.is_dir() else None
    if meta is not None and meta.is_file():
        try:
            info = read_metadata(meta, limits).get("rosbag2_bagfile_information", {})
            name = (info.get("custom_data") or {}).get(ROBOT_KEY)
            if name:
                return str(name)
        except (BagError, OSError, AttributeError):
            pass
    if root is not None and path != root and path.parent.resolve() == root.resolve():
        return path.stem if path.is_file() else path.name
    return path.parent.name or str(path.parent)


# ------------------------------------------------------------------------------ one recording
def analyze_one(path: str, key: str, options: Options, limits: ReadLimits | None = None) -> Result:
    """Analyse one recording (the task a worker runs), read within ``limits`` (default: :class:`ReadLimits`'s,
    as ``analyze_bag``'s); never raises for a bad recording."""
    from shaper_nodes.recordings import describe_damage

    from .analyze import analyze
    from .streams import read_recording

    started = time.perf_counter()
    p = pathlib.Path(path)
    out = Result(path=str(path), key=key, robot=robot_of(p, limits))
    try:
        rec = read_recording(p, limits=limits)
        an = analyze(rec, options)
    except Exception as err:  # reported per recording: one bad file must not stop the fleet
        out.error = f"{type(err).__name__}: {err}"
        out.seconds = time.perf_counter() - started
        return out
    out.start_s = float(rec.accel.t[0])
    out.cycles = len(an.cycles)
    out.damage = [describe_damage(d) for d in rec.damage]
    ranked = sorted(an.modes, key=lambda m: (bool(an.ringing_issue(m)), -m.amplitude))
    out.modes = [{"frequency_hz": m.hz, "frequency_std_hz": m.omega_std / (2 * math.pi), "zeta": m.zeta,
                  "zeta_std": m.zeta_std, "amplitude": m.amplitude, "method": m.method,
                  "rings": not an.ringing_issue(m)} for m in ranked]
    out.headline = list(an.headline)
    out.groups = [sorted(m.hz for m in g.modes if not an.ringing_issue(m))
                  for g in sorted(an.groups, key=lambda g: g.rows[0])]
    best = an.recommendation.best if an.recommendation is not None else None
    if best is not None:
        out.recommendation = {"family": best.family, "duration_s": best.duration,
                              "v_nominal": best.nominal_vibration, "v_worst": best.worst_vibration}
    out.seconds = time.perf_counter() - started
    return out


# ------------------------------------------------------------------------------ the cache
class Cache:
    """One small JSON file per content key, under ``folder`` (created when first written)."""

    def __init__(self, folder: str | pathlib.Path) -> None:
        self.folder = pathlib.Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise FleetError(f"cache {self.folder}: exists and is not a folder")

    def _file(self, key: str) -> pathlib.Path:
        return self.folder / key[:2] / f"{key}.json"

    def get(self, key: str) -> Result | None:
        """The cached result, or None (missing or unreadable: analysed again)."""
        try:
            res = Result.from_json(json.loads(self._file(key).read_text()))
        except (OSError, ValueError, TypeError):
            return None
        return res if res.version == ANALYSIS_VERSION and res.key == key else None

    def put(self, res: Result) -> None:
        """Store ``res`` (atomically: written beside, then renamed)."""
        f = self._file(res.key)
        f.parent.mkdir(parents=True, exist_ok=True)
        tmp = f.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(json.dumps(res.to_json(), allow_nan=False))
        tmp.replace(f)


# ------------------------------------------------------------------------------ the fleet
@dataclass
class FleetRun:
    """The results of a fleet run, in the order of the recordings, and what the run did."""

    results: list[Result]
    analysed: int
    cached: int
    seconds: float
    where: str
    startup_s: float = 0.0  # of that, starting (or connecting to) the cluster and importing the analysis on its workers


def _bar(total: int, show: bool) -> Any:
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="rec", desc="analyze_fleet", file=sys.stderr, dynamic_ncols=True)


def make_cluster(workers: int, processes: bool = True) -> Any:
    """A local Dask cluster of ``workers`` workers, one thread each, one BLAS thread each."""
    from distributed import LocalCluster

    for k, v in SINGLE_THREAD.items():  # inherited by the worker processes (and threads of this one)
        os.environ.setdefault(k, v)
    extra: dict[str, Any] = {"env": dict(SINGLE_THREAD)} if processes else {}  # the Nanny's, for its worker
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=processes, dashboard_address=":0",
                        **extra)


def _worker_env() -> dict[str, str | None]:
    return {k: os.environ.get(k) for k in SINGLE_THREAD}


def _preload() -> None:
    """On each worker: import the analysis (numpy, scipy, rosbags) once, before the tasks come."""
    from . import analyze, streams  # noqa: F401


def run_fleet(paths: Iterable[pathlib.Path], options: Options, cache: Cache | None, *, workers: int = 1,
              scheduler: str | None = None, processes: bool = True, progress: bool = False,
              warn: Callable[[str], None] = lambda s: None, limits: ReadLimits | None = None,
              root: pathlib.Path | None = None) -> FleetRun:
    """Analyse the recordings not in the cache; returns every result (cached or new), in order.

    Each result's robot is :func:`robot_of` the recording under the fleet's folder ``root`` (found
    again for cached results: the folder a recording sits in is not part of its content key).

    Every recording is read within ``limits`` (default: :class:`ReadLimits`'s, as ``analyze_bag``'s).

    ``workers`` 0 (and no ``scheduler``): a plain loop in this process. Otherwise a Dask client on
    the cluster at ``scheduler`` or on a new local cluster of ``workers`` (``processes`` False: threads
    of this process, for tests). Unreadable files give a result with an error.
    """
    started = time.perf_counter()
    paths = list(paths)
    results: list[Result | None] = [None] * len(paths)
    todo: list[tuple[int, str]] = []
    cached = 0
    for i, p in enumerate(paths):
        try:
            key = content_key(p, options, limits)
        except OSError as err:
            results[i] = Result(str(p), "", robot_of(p, limits), error=f"cannot read: {err}")
            continue
        hit = cache.get(key) if cache is not None else None
        if hit is not None:
            hit.path, hit.seconds = str(p), 0.0
            results[i] = hit
            cached += 1
        else:
            todo.append((i, key))
    bar = _bar(len(todo), progress and bool(todo))

    def done(i: int, res: Result) -> None:
        results[i] = res
        if cache is not None and res.key:
            cache.put(res)
        if bar is not None:
            bar.update(1)

    where, startup = "cache only", [0.0]
    try:
        if todo and workers == 0 and not scheduler:
            where = "serial (this process)"
            for i, key in todo:
                done(i, analyze_one(str(paths[i]), key, options, limits))
        elif todo:
            where = _run_dask(paths, todo, options, done, workers, scheduler, processes, warn, startup, limits)
    finally:
        if bar is not None:
            bar.close()
    out = [r for r in results if r is not None]
    for r in out:
        r.robot = robot_of(pathlib.Path(r.path), limits, root)
    return FleetRun(out, len(todo), cached, time.perf_counter() - started, where, startup[0])


def _run_dask(paths: list[pathlib.Path], todo: list[tuple[int, str]], options: Options,
              done: Callable[[int, Result], None], workers: int, scheduler: str | None, processes: bool,
              warn: Callable[[str], None], startup: list[float], limits: ReadLimits | None = None) -> str:
    from distributed import Client, as_completed

    started = time.perf_counter()
    cluster = None if scheduler else make_cluster(max(workers, 1), processes)
    try:
        with Client(scheduler if scheduler else cluster) as client:
            client.run(_preload)
            startup[0] = time.perf_counter() - started
            where = f"Dask scheduler {scheduler}" if scheduler else (
                f"local Dask cluster, {max(workers, 1)} worker {'processes' if processes else 'threads'}")
            if scheduler:  # a cluster started elsewhere: say so if its workers run several BLAS threads
                envs = client.run(_worker_env)
                many = sorted(w for w, env in envs.items() if any(v != "1" for v in env.values()))
                if many:
                    warn(f"workers {', '.join(many)} do not limit BLAS to one thread ({SINGLE_THREAD} unset):"
                         " on few cores the analysis runs slower; start them with these variables set")
            futures = {}
            for i, key in todo:
                f = client.submit(analyze_one, str(paths[i]), key, options, limits, key=f"analyze-{key}-{i}",
                                  pure=False)
                futures[f] = (i, key)
            for f in as_completed(futures):
                i, key = futures[f]
                try:
                    res = f.result()
                except Exception as err:  # the worker died or the task could not run: not cached
                    res = Result(str(paths[i]), "", robot_of(paths[i], limits), error=f"{type(err).__name__}: {err}")
                done(i, res)
            return where
    finally:
        if cluster is not None:
            cluster.close()
