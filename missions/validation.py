"""The one range check behind every settings dataclass: a clear one-line error naming the field."""
from __future__ import annotations

import math
from typing import Iterable


def check_number(owner: str, name: str, value: object, low: float, high: float, integer: bool = False) -> None:
    """Raise ``ValueError("Owner.name must be a number in [low, high], got value")`` unless ``value`` is a finite
    number in range (bools refused: ``True`` is an int to Python, never a meaningful setting)."""
    ok = (not isinstance(value, bool) and isinstance(value, (int, float)) and is_finite(value)
          and low <= value <= high and (not integer or int(value) == value))
    if not ok:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"{owner}.{name} must be {kind} in [{low:g}, {high:g}], got {brief(value)}")


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


def check_fields(owner: object, rules: Iterable[tuple[str, float, float]], integers: Iterable[str] = ()) -> None:
    """:func:`check_number` for each ``(field name, low, high)`` of a dataclass instance."""
    integers = set(integers)
    for name, low, high in rules:
        check_number(type(owner).__name__, name, getattr(owner, name), low, high, integer=name in integers)
