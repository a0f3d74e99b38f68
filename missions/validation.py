"""The one range check behind every settings dataclass: a clear one-line error naming the field, the value and the
allowed range, e.g. ``FlightSettings.altitude_m must be a number in [10, 120], got 500``.

A dataclass's ``__post_init__`` calls :func:`check_fields` with a table of its fields' ranges (or
:func:`check_number` / :func:`check_in` for one field). A range is ``(low, high)``, both ends included, or an
:class:`Interval` for open ends, one-sided ranges and integers; :data:`FINITE`, :data:`POSITIVE`,
:data:`NON_NEGATIVE` and :data:`COUNT` name the usual ones.
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class Interval:
    """The numbers a setting may take: from ``low`` to ``high`` (infinite: no bound on that side), each end
    included unless marked open; ``integer`` takes integers only (``int`` or numpy's, not ``3.0``). Any value in
    it is finite, and never a bool (``True`` is an int to Python, never a meaningful setting)."""

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    integer: bool = False

    def __contains__(self, value: object) -> bool:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral if self.integer else numbers.Real):
            return False
        if not is_finite(value):
            return False
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        """The allowed values in words: "a number in [0, 1)", "a finite number > 0", "an integer >= 1"."""
        bounded_low, bounded_high = math.isfinite(self.low), math.isfinite(self.high)
        kind = "an integer" if self.integer else "a number" if bounded_low and bounded_high else "a finite number"
        if bounded_low and bounded_high:
            return (f"{kind} in {'(' if self.low_open else '['}{_bound(self.low)}, "
                    f"{_bound(self.high)}{')' if self.high_open else ']'}")
        if bounded_low:
            return f"{kind} {'>' if self.low_open else '>='} {_bound(self.low)}"
        if bounded_high:
            return f"{kind} {'<' if self.high_open else '<='} {_bound(self.high)}"
        return kind


FINITE = Interval()
"""Any finite number."""
POSITIVE = Interval(0.0, low_open=True)
"""A finite number > 0: time constants, noise levels that must not vanish, rates."""
NON_NEGATIVE = Interval(0.0)
"""A finite number >= 0."""
COUNT = Interval(1, integer=True)
"""An integer >= 1."""


def check_in(owner: str, name: str, value: object, allowed: Interval, hint: str = "") -> None:
    """Raise ``ValueError("Owner.name must be <allowed>, got value<hint>")`` unless ``value`` is in ``allowed``;
    ``hint`` (such as ``"; try the default 0.5"``) ends the message."""
    if value not in allowed:
        raise ValueError(f"{owner}.{name} must be {allowed}, got {brief(value)}{hint}")


def check_choice(owner: str, name: str, value: object, choices: Iterable[str]) -> None:
    """Raise ``ValueError("Owner.name must be 'a' or 'b', got value")`` unless ``value`` is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        listed = " or ".join(map(repr, choices)) if len(choices) <= 2 else \
            "one of " + ", ".join(map(repr, choices))
        raise ValueError(f"{owner}.{name} must be {listed}, got {brief(value)}")


def check_number(owner: str, name: str, value: object, low: float, high: float, integer: bool = False) -> None:
    """:func:`check_in` with the range ``[low, high]``, both ends included."""
    check_in(owner, name, value, Interval(low, high, integer=integer))


def check_fields(owner: object, rules: Iterable[tuple[str, float, float] | tuple[str, Interval]],
                 integers: Iterable[str] = ()) -> None:
    """:func:`check_in` for each rule of a dataclass instance: ``(field name, low, high)``, both ends included
    (an integer range for the fields named in ``integers``), or ``(field name, Interval)``."""
    integers = set(integers)
    for name, *bounds in rules:
        allowed = bounds[0] if len(bounds) == 1 else Interval(bounds[0], bounds[1], integer=name in integers)
        check_in(type(owner).__name__, name, getattr(owner, name), allowed)


def is_finite(value: int | float) -> bool:
    """``math.isfinite`` that says False, instead of raising OverflowError, for an int beyond float range."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def brief(value: object, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters: a 400-digit number from a file must not flood the message."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 3]}... ({len(text)} characters)"


def _bound(value: float) -> str:
    """A range's end as people write it: integers in full (4294967295, not 4.29497e+09), floats short (1e+07)."""
    return str(value) if isinstance(value, numbers.Integral) else f"{value:g}"
