"""One way to declare parameters and their allowed values.

A parameter class is a frozen dataclass deriving from Parameters. Each field states what it allows
beside its default — `max_vel_x: float = param(0.5, gt=0)   # m/s`, the unit and meaning in the
comment — and a relation between fields is a Rule in the class's `rules`. Building the object
(directly, or from a mapping by from_mapping.load_params) checks every field, then every rule of
the class and of its bases, and stops at the first violation with one line naming the parameter,
what it allows and the value given: "parameter max_vel_x must be > 0, got -1.0". A subclass adds
fields and rules; it never redeclares an inherited field (tests/test_house.py).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from numbers import Real
from typing import Any, Callable, ClassVar

ALLOWED = "omninav.allowed"     # the dataclass field metadata key holding a field's Allowed


class ParamError(ValueError):
    """A parameter that is unknown, of the wrong type or out of range; says which and where."""


@dataclass(frozen=True)
class Allowed:
    """What one field allows. Bounds apply to a number, or to each number of a sequence; a bound
    also requires the number to be finite. None passes (an optional field left unset)."""
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    finite: bool = False            # any finite number (a bound implies it)
    choices: tuple = ()             # the values allowed (of each item, for a sequence)
    nonempty: bool = False          # a string or sequence that is not empty
    items: int | None = None        # a sequence of exactly this many items
    min_items: int = 0              # a sequence of at least this many items ...
    or_empty: bool = False          # ... or of none (a footprint left empty: robot_radius instead)

    def problem(self, value: Any) -> str:
        """'' when `value` is allowed, else what is allowed ("> 0", "one of 'a', 'b'")."""
        if value is None:
            return ""
        if self.nonempty and not value:
            return "non-empty"
        if isinstance(value, (tuple, list)):
            if self.items is not None and len(value) != self.items:
                return f"{self.items} items"
            if len(value) < self.min_items and not (self.or_empty and not value):
                return ("empty or " if self.or_empty else "") + f"at least {self.min_items} items"
            if self.choices and not all(v in self.choices for v in value):
                return "a list of " + ", ".join(map(repr, self.choices))
            if self._numeric and not all(self._number_allowed(v) for v in value):
                return f"a list of numbers each {self._range()}"
            return ""
        if self.choices and value not in self.choices:
            return "one of " + ", ".join(map(repr, self.choices))
        if self._numeric and not self._number_allowed(value):
            return self._range()
        return ""

    @property
    def _numeric(self) -> bool:
        return self.finite or any(b is not None for b in (self.ge, self.gt, self.le, self.lt))

    def _number_allowed(self, value: Any) -> bool:
        if not isinstance(value, Real) or not math.isfinite(value):
            return False
        return ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))

    def _range(self) -> str:
        low = f"[{self.ge}" if self.ge is not None else f"({self.gt}" if self.gt is not None else None
        high = f"{self.le}]" if self.le is not None else f"{self.lt})" if self.lt is not None else None
        if low and high:
            return f"in {low}, {high}"
        if low:
            return f"≥ {self.ge}" if self.ge is not None else f"> {self.gt}"
        if high:
            return f"≤ {self.le}" if self.le is not None else f"< {self.lt}"
        return "a finite number"


def param(default: Any = dataclasses.MISSING, *, default_factory: Any = dataclasses.MISSING, **allowed: Any) -> Any:
    """A parameter field: its default and what it allows (the keywords of Allowed)."""
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={ALLOWED: Allowed(**allowed)})


@dataclass(frozen=True)
class Rule:
    """A relation between fields, blamed on one: `holds(params)` true, else "parameter {name} must
    be {what}, got {value}", `what` formatted with the params as p ("≥ min_particles
    ({p.min_particles})"); `shown` picks what the message shows as given (default: the field).
    `holds` may raise ParamError itself when it builds a nested group that says better what is wrong."""
    name: str
    holds: Callable[[Any], bool]
    what: str
    shown: Callable[[Any], Any] | None = None


class Parameters:
    """Base of every parameter dataclass: construction checks each field and each rule."""
    rules: ClassVar[tuple[Rule, ...]] = ()

    def __post_init__(self) -> None:
        check(self)


def check(params: Any) -> None:
    """ParamError naming the first field outside what it allows, or the first rule that fails
    (the bases' rules before the class's own)."""
    for f in dataclasses.fields(params):
        allowed = f.metadata.get(ALLOWED)
        value = getattr(params, f.name)
        problem = allowed.problem(value) if allowed else ""
        if problem:
            raise ParamError(f"parameter {f.name} must be {problem}, got {value!r}")
    for rule in rules_of(type(params)):
        if not rule.holds(params):
            given = rule.shown(params) if rule.shown else getattr(params, rule.name)
            raise ParamError(f"parameter {rule.name} must be {rule.what.format(p=params)}, got {given!r}")


def rules_of(cls: type) -> list[Rule]:
    """The rules a class and its bases declare, the bases' first."""
    return [rule for klass in reversed(cls.__mro__) for rule in vars(klass).get("rules", ())]


def group(params: Any, cls: type) -> Any:
    """The parameter group `cls` (a class whose fields `params` has too, e.g. one of its bases) with
    the values of `params`: what one model or core reads of a larger parameter class."""
    return cls(**{f.name: getattr(params, f.name) for f in dataclasses.fields(cls) if f.init})
