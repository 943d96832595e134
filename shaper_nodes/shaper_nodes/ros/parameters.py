"""Parameter tables: each node's parameters written once, and declared from the table.

A node's table is a tuple of :class:`Spec` (name, default or type, description with units,
inclusive range or choices, read-only). :func:`declare_all` declares every entry with a
``ParameterDescriptor`` (so ``ros2 param describe`` explains it and rclpy enforces the range),
refuses a start-up value outside the choices, and refuses later changes of a dynamic parameter
outside its choices. :func:`values` reads them back.

Where the core validates the same value (the learner's ``ListConfig``, the MRILC model, a
shaper design), the entry's ``check`` runs the core's validation on one value; the test
``test_parameter_tables`` walks every table and checks that the core accepts each range edge,
so that the node never accepts what the core then refuses.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter


@dataclass(frozen=True)
class Spec:
    """One parameter of a node.

    Attributes
    ----------
    name : str
        Full name (``list.max_step_t2``).
    default : object
        Default value; ``None`` for a parameter without one (then ``type`` is required).
    description : str
        Meaning and units.
    range : (float, float), optional
        Inclusive range of a number (integers if the default is an int).
    choices : tuple of str
        The values a string may take (empty: any).
    read_only : bool
        Set at start-up only.
    type : Parameter.Type, optional
        The type of a parameter without a default.
    check : callable, optional
        The core's validation of one value of this parameter (raises ``ValueError`` if the core
        refuses it); used by the tests that hold the table against the core.
    """

    name: str
    default: Any
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    type: Parameter.Type | None = None
    check: Callable[[Any], object] | None = None

    @property
    def integer(self) -> bool:
        return isinstance(self.default, int) and not isinstance(self.default, bool)

    def descriptor(self) -> ParameterDescriptor:
        text = self.description
        if self.choices:
            text += " One of: " + ", ".join(repr(c) for c in self.choices) + "."
        d = ParameterDescriptor(description=text, read_only=self.read_only)
        if self.range is not None:
            lo, hi = self.range
            if self.integer:
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        return d

    def refusal(self, value: Any) -> str | None:
        """Why ``value`` is not one of the choices (None if it is, or if any value goes)."""
        if self.choices and value not in self.choices:
            return f"parameter {self.name} must be one of {', '.join(map(repr, self.choices))}, got {value!r}"
        return None


def describe(text: str, lo: float | None = None, hi: float | None = None, *, integer: bool = False,
             read_only: bool = False) -> ParameterDescriptor:
    """A ParameterDescriptor with ``text``, an inclusive range [lo, hi] if given, and read-only flag
    (for parameters declared one by one, such as a rule base's per-rule entries)."""
    d = ParameterDescriptor(description=text, read_only=read_only)
    if lo is not None and hi is not None:
        if integer:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return d


def declare_all(node: Node, table: Iterable[Spec]) -> None:
    """Declare every parameter of ``table`` on ``node``.

    Raises
    ------
    ValueError
        A start-up value is not one of its parameter's choices (the message names both).
    """
    specs = {s.name: s for s in table}
    for spec in specs.values():
        if spec.default is None:
            if spec.type is None:
                raise TypeError(f"parameter {spec.name}: a spec without a default needs a type")
            node.declare_parameter(spec.name, spec.type, spec.descriptor())
        else:
            node.declare_parameter(spec.name, spec.default, spec.descriptor())
        if spec.choices:
            why = spec.refusal(node.get_parameter(spec.name).value)
            if why:
                raise ValueError(why)

    def on_set(params: list[Parameter]) -> SetParametersResult:
        for p in params:
            spec = specs.get(p.name)
            why = spec.refusal(p.value) if spec is not None else None
            if why:
                return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)

    if any(s.choices and not s.read_only for s in specs.values()):
        node.add_on_set_parameters_callback(on_set)


def values(node: Node, table: Iterable[Spec] | Iterable[str], prefix: str = "") -> dict[str, Any]:
    """The present values of ``table``'s parameters (``None`` for one without a value), keyed by
    name with ``prefix`` removed (only the names that start with it)."""
    out: dict[str, Any] = {}
    for item in table:
        name = item.name if isinstance(item, Spec) else item
        if not name.startswith(prefix):
            continue
        try:
            out[name[len(prefix):]] = node.get_parameter(name).value
        except ParameterUninitializedException:
            out[name[len(prefix):]] = None
    return out


def topics(defaults: Mapping[str, str]) -> tuple[Spec, ...]:
    """``topics.<key>`` entries (read-only topic names) for a node's inputs and outputs."""
    return tuple(Spec(f"topics.{key}", default, f"Topic name ({key}).", read_only=True)
                 for key, default in defaults.items())
