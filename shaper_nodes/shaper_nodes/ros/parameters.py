"""Parameter tables: each node's parameters written once, and declared from the table.

A node's table is a tuple of :class:`Spec` (name, default or type, description with units,
inclusive range or choices, read-only). :func:`declare_all` declares every entry with a
``ParameterDescriptor`` (so ``ros2 param describe`` explains it and rclpy enforces the range),
refuses a start-up value outside the choices, and refuses later changes of a dynamic parameter
outside its choices. :func:`values` reads them back.

Every parameter has a value after :func:`declare_all` (``ros2 param dump`` lists them all): a
spec without a default is an array whose default is the empty array of its type, which the nodes
read as "not set". Values are taken as ``ros2 param set`` and params YAML files write them: a
double parameter takes an integer (``8`` is ``8.0``, range still checked), a double array an
integer array, and an array parameter an empty array of any type (``[]`` carries no type); any
other type is refused with a reason naming the expected one. Such a parameter is declared with
``dynamic_typing`` (so that a start-up value of another type reaches :func:`declare_all`, which
converts it or refuses it), then given its static type; later a pre-set callback converts what a
parameter service request sends before rclpy checks type and range (added once per node, whatever
the number of tables declared on it).

Where the core validates the same value (the learner's ``ListConfig``, the MRILC model, a
shaper design), the entry's ``check`` runs the core's validation on one value; the test
``test_parameter_tables`` walks every table and checks that the core accepts each range edge,
so that the node never accepts what the core then refuses.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

_T = Parameter.Type
#: the array types (an empty array of any of them is taken by an array parameter of any other)
ARRAYS = frozenset({_T.BYTE_ARRAY, _T.BOOL_ARRAY, _T.INTEGER_ARRAY, _T.DOUBLE_ARRAY, _T.STRING_ARRAY})
#: how a type is named in a refusal and in --help
TYPE_NAMES = {_T.NOT_SET: "no value", _T.BOOL: "bool", _T.INTEGER: "integer", _T.DOUBLE: "double",
              _T.STRING: "string", _T.BYTE_ARRAY: "byte array", _T.BOOL_ARRAY: "bool array",
              _T.INTEGER_ARRAY: "integer array", _T.DOUBLE_ARRAY: "double array", _T.STRING_ARRAY: "string array"}


def _a(typ: Parameter.Type) -> str:
    """A type's name with its article ("an integer", "a double")."""
    name = TYPE_NAMES[typ]
    return ("an " if name[0] in "aeiou" else "a ") + name


def type_of(value: Any) -> Parameter.Type:
    """The parameter type of a (non-empty) default value.

    Raises
    ------
    TypeError
        ``value`` is an empty list (its type cannot be told: give the spec a ``type`` and no default)
        or not a parameter value.
    """
    if isinstance(value, (list, tuple)) and not value:
        raise TypeError("an empty list does not say its type: give the spec a type and default None")
    return Parameter.Type.from_parameter_value(list(value) if isinstance(value, tuple) else value)


@dataclass(frozen=True)
class Spec:
    """One parameter of a node.

    Attributes
    ----------
    name : str
        Full name (``list.max_step_t2``).
    default : object
        Default value; ``None`` for an array parameter without one (then ``type`` is required and
        the parameter's default is the empty array of that type, read as "not set").
    description : str
        Meaning and units.
    range : (float, float), optional
        Inclusive range of a number (integers if the default is an int).
    choices : tuple of str
        The values a string may take (empty: any).
    read_only : bool
        Set at start-up only.
    type : Parameter.Type, optional
        The type of a parameter without a default (an array type).
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

    @property
    def param_type(self) -> Parameter.Type:
        """The parameter's type (``type``, else the default's)."""
        return self.type if self.type is not None else type_of(self.default)

    @property
    def initial(self) -> Any:
        """The value declared: the default, or the empty array for a spec without one."""
        return [] if self.default is None else self.default

    @property
    def converts(self) -> bool:
        """Whether values of some other types are converted to this one (doubles and arrays; see
        :meth:`convert`): :func:`declare_all` declares such a parameter with dynamic typing, then
        gives it its static type."""
        return self.param_type == _T.DOUBLE or self.param_type in ARRAYS

    def descriptor(self, read_only: bool | None = None, dynamic_typing: bool = False) -> ParameterDescriptor:
        """The parameter's descriptor (``read_only`` overrides the spec's)."""
        text = self.description
        if self.choices:
            text += " One of: " + ", ".join(repr(c) for c in self.choices) + "."
        d = ParameterDescriptor(description=text, read_only=self.read_only if read_only is None else read_only,
                                type=self.param_type.value, dynamic_typing=dynamic_typing)
        if self.param_type == _T.DOUBLE:
            d.additional_constraints = "An integer is taken as a double."
        elif self.param_type == _T.DOUBLE_ARRAY:
            d.additional_constraints = "Integers are taken as doubles."
        if self.range is not None:
            lo, hi = self.range
            if self.integer:
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        return d

    def convert(self, param: Parameter) -> Parameter:
        """``param`` converted to this spec's type where the value says the same: an integer to a
        double, an integer array to a double array, an empty array of any type to this array type;
        ``param`` itself otherwise (also when it has the right type already)."""
        want, got = self.param_type, param.type_
        if got == want or not self.converts:
            return param
        if want == _T.DOUBLE and got == _T.INTEGER:
            return Parameter(param.name, _T.DOUBLE, float(param.value))
        if want in ARRAYS and got in ARRAYS and len(param.value) == 0:
            return Parameter(param.name, want, [])
        if want == _T.DOUBLE_ARRAY and got == _T.INTEGER_ARRAY:
            return Parameter(param.name, want, [float(v) for v in param.value])
        return param

    def type_refusal(self, param: Parameter) -> str | None:
        """Why ``param`` (after :meth:`convert`) does not have this spec's type (None if it does)."""
        want, got = self.param_type, param.type_
        if got == want:
            return None
        if got == _T.NOT_SET:
            return f"parameter {self.name} takes {_a(want)} and cannot be unset"
        note = " (an integer is taken as a double)" if want in (_T.DOUBLE, _T.DOUBLE_ARRAY) else ""
        return f"parameter {self.name} takes {_a(want)}{note}, got {_a(got)} {param.value!r}"

    def refusal(self, value: Any) -> str | None:
        """Why ``value`` is not one of the choices (None if it is, or if any value goes)."""
        if self.choices and value not in self.choices:
            return f"parameter {self.name} must be one of {', '.join(map(repr, self.choices))}, got {value!r}"
        return None


class _Declared:
    """The specs declared on one node and the callbacks that convert and check their values
    (added once per node: rclpy concatenates what several pre-set callbacks return)."""

    def __init__(self, node: Node) -> None:
        self.specs: dict[str, Spec] = {}
        node.add_pre_set_parameters_callback(self.pre_set)
        node.add_on_set_parameters_callback(self.on_set)

    def pre_set(self, params: list[Parameter]) -> list[Parameter]:
        """Convert what a ``ros2 param set`` or a parameter service request sends (see Spec.convert),
        before rclpy checks its type and range."""
        return [self.specs[p.name].convert(p) if p.name in self.specs else p for p in params]

    def on_set(self, params: list[Parameter]) -> SetParametersResult:
        """Refuse a value of another type (a start-up value while the parameter is dynamically typed;
        later rclpy refuses it first) or outside the choices."""
        for p in params:
            spec = self.specs.get(p.name)
            if spec is None:
                continue
            why = spec.type_refusal(spec.convert(p)) or spec.refusal(p.value)
            if why:
                return SetParametersResult(successful=False, reason=why)
        return SetParametersResult(successful=True)


_DECLARED: weakref.WeakKeyDictionary[Node, _Declared] = weakref.WeakKeyDictionary()


def declare_all(node: Node, table: Iterable[Spec]) -> None:
    """Declare every parameter of ``table`` on ``node`` (may be called more than once on a node).

    Each parameter gets its value: the start-up value (params file, ``-p``, ``parameter_overrides``),
    converted to the parameter's type where it says the same (``5`` for a double), else the
    spec's default (an empty array for a spec without one).

    Raises
    ------
    ValueError
        A start-up value is of the wrong type, out of range, or not one of its parameter's choices
        (the message names the parameter and the problem).
    """
    declared = _DECLARED.get(node)
    if declared is None:
        declared = _DECLARED[node] = _Declared(node)
    for spec in table:
        if spec.default is None and spec.type not in ARRAYS:
            raise TypeError(f"parameter {spec.name}: a spec without a default needs an array type")
        declared.specs[spec.name] = spec
        final = spec.descriptor()
        # declared dynamically typed and writable: its start-up value is converted, then the type fixed
        first = spec.descriptor(read_only=False, dynamic_typing=True) if spec.converts else final
        try:
            node.declare_parameter(spec.name, spec.initial, first)
            param = node.get_parameter(spec.name)
            converted = spec.convert(param)
            if converted is not param:
                result = node.set_parameters([converted])[0]
                if not result.successful:
                    reason = result.reason
                    raise ValueError(reason if reason.lower().startswith("parameter ") else
                                     f"parameter {spec.name}: {reason}")
            if first is not final:
                node.set_descriptor(spec.name, final)
        except InvalidParameterTypeException:
            raise ValueError(f"parameter {spec.name} takes {_a(spec.param_type)}") from None
        except InvalidParameterValueException as err:
            reason = str(err).split("Reason: ", 1)[-1].removesuffix(f": {spec.name}")
            raise ValueError(reason if reason.lower().startswith("parameter ")
                             else f"parameter {spec.name}: {reason}") from None


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
