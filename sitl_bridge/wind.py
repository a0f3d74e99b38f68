"""Wind over the search area: a steady NED air velocity plus deterministic gusts, and the drift the gusts cause.

Gusts are a function of absolute simulated time, which is what lets their displacement be integrated exactly
for any step size (see ``sitl_bridge/airborne.py``).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from missions.validation import FINITE, NON_NEGATIVE, check_fields
from sitl_bridge.multirotor import MultirotorParams
from sitl_bridge.scalar_math import ScalarMath

GUSTS_PER_AXIS = 3
GUST_PERIOD_RANGE_S = (3.0, 30.0)
VERTICAL_GUST_FRACTION = 0.3  # vertical gusts are this fraction of the horizontal ones
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class Wind:
    """Steady wind (NED velocity of the air, m/s) plus deterministic gusts.

    Gusts are, per axis, a sum of :data:`GUSTS_PER_AXIS` sinusoids whose periods (3-30 s), phases and
    relative weights are drawn once from ``random.Random(seed)``. The horizontal RMS gust speed is
    ``gust_mps``; vertical gusts are :data:`VERTICAL_GUST_FRACTION` of that. Being a function of absolute
    time is what lets :func:`gust_drift` integrate them exactly for any step.
    """

    north_mps: float = 0.0
    east_mps: float = 0.0
    gust_mps: float = 0.0  # horizontal RMS gust speed, m/s; 0 = no gusts
    seed: int = 0  # picks the gust periods, phases and weights
    # Per axis (north, east, down): tuple of (amplitude m/s, angular frequency rad/s, phase rad,
    # amplitude / angular frequency m), the last one precomputed for the displacement integral.
    _terms: tuple = field(init=False, repr=False, compare=False)
    _last_gust: list = field(init=False, repr=False, compare=False)  # [(time, gust)]: asked twice per physics tick

    def __post_init__(self) -> None:
        check_fields(self, (("north_mps", FINITE), ("east_mps", FINITE), ("gust_mps", NON_NEGATIVE)))
        rng = random.Random(self.seed)
        log_lo, log_hi = (math.log(p) for p in GUST_PERIOD_RANGE_S)
        terms = []
        for axis_scale in (1.0, 1.0, VERTICAL_GUST_FRACTION):
            periods = [math.exp(rng.uniform(log_lo, log_hi)) for _ in range(GUSTS_PER_AXIS)]
            weights = [rng.uniform(0.5, 1.0) for _ in range(GUSTS_PER_AXIS)]
            phases = [rng.uniform(0.0, _TWO_PI) for _ in range(GUSTS_PER_AXIS)]
            # RMS of a sinusoid sum is sqrt(sum(A^2) / 2) per axis; sum(A^2) = gust^2 makes the
            # horizontal (two-axis) RMS speed equal gust_mps.
            norm = self.gust_mps * axis_scale / math.sqrt(sum(w * w for w in weights))
            terms.append(tuple((w * norm, _TWO_PI / p, ph, w * norm * p / _TWO_PI)
                               for w, p, ph in zip(weights, periods, phases)))
        object.__setattr__(self, "_terms", tuple(terms))
        object.__setattr__(self, "_last_gust", [(None, (0.0, 0.0, 0.0))])

    def gust_velocity(self, time_s: float) -> tuple[float, float, float]:
        """Gust part of the air velocity (NED, m/s) at absolute simulated time ``time_s``."""
        when, gust = self._last_gust[0]
        if when != time_s:
            gust = tuple(sum(a * math.sin(w * time_s + ph) for a, w, ph, _ in axis) for axis in self._terms)
            self._last_gust[0] = (time_s, gust)
        return gust


def axis_displacement(terms: tuple, t0_s, t1_s, xp=ScalarMath):
    """Integral over [t0, t1] of sum(a * sin(w t + ph)) = sum(a / w * (cos(w t0 + ph) - cos(w t1 + ph)))."""
    total = 0.0
    for _, w, ph, a_over_w in terms:  # the few sinusoids of one axis (a loop over terms, not vehicles)
        total = total + a_over_w * (xp.cos(w * t0_s + ph) - xp.cos(w * t1_s + ph))
    return total


def gust_drift(params: MultirotorParams, wind: Wind, t0, t1, xp=ScalarMath):
    """Horizontal displacement (north, east; m) over [t0, t1] by the gusts the controller lets through."""
    if wind.gust_mps == 0.0 or params.gust_response == 0.0:  # (parameters, not state: no per-vehicle if)
        return 0.0, 0.0
    north, east, _ = wind._terms
    r = params.gust_response
    return r * axis_displacement(north, t0, t1, xp), r * axis_displacement(east, t0, t1, xp)
