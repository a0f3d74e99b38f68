"""numpy's names for Python floats, so that one piece of vehicle physics steps one vehicle (floats) or N (arrays).

The airborne physics (``sitl_bridge/airborne.py``) is written with no Python ``if`` on values: only arithmetic,
``abs`` and ``xp.where/minimum/maximum/clip/isfinite/hypot/copysign/expm1/cos/fmod``. With ``xp=numpy`` it steps
arrays of N vehicles; with ``xp=ScalarMath`` one vehicle, nearly as fast as plain scalar code.
"""
from __future__ import annotations

import math

_PI, _TWO_PI = math.pi, 2.0 * math.pi


class ScalarMath:
    """numpy's names for the functions the shared physics uses, for Python floats: ``math`` and conditional
    expressions (faster than numpy or min/max on one float). As with numpy, all arguments are evaluated."""

    isfinite, hypot, copysign = math.isfinite, math.hypot, math.copysign
    expm1, cos, fmod = math.expm1, math.cos, math.fmod
    where = staticmethod(lambda condition, if_true, if_false: if_true if condition else if_false)
    minimum = staticmethod(lambda a, b: a if a < b else b)
    maximum = staticmethod(lambda a, b: a if a > b else b)
    clip = staticmethod(lambda x, lo, hi: lo if x < lo else hi if x > hi else x)


def wrap_angle(angle_rad, xp=ScalarMath):
    """Wrap an angle to (-pi, pi], exactly (fmod is exact, and so is the one +-2pi correction)."""
    r = xp.fmod(angle_rad, _TWO_PI)  # in (-2pi, 2pi)
    return xp.where(r > _PI, r - _TWO_PI, xp.where(r <= -_PI, r + _TWO_PI, r))
