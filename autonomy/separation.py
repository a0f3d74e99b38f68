"""Keeping a fleet's drones apart: the separation rule, the shield each runner puts on its setpoints, and the
watch that records the closest approach.

Two drones are **separated** while they are at least ``horizontal_m`` apart horizontally *or* at least
``vertical_m`` apart in height, as air traffic control separates aircraft laterally or vertically. A fleet
searches in altitude layers (``missions.fleet.Fleet.altitude_layer_m``) and keeps ``separation_m`` horizontally;
``vertical_m`` is half a layer, so drones on different layers are separated and a drone that has left its layer
(a close look, a climb) is not.

The **shield** (:func:`separated_velocity`) runs on every setpoint a fleet drone's runner streams while it
searches, with the other drones' filtered positions and velocities: for each drone not separated by height and
within ``horizontal_m`` plus ``lookahead_s`` of flight, it removes the part of the velocity that closes on it and,
within ``PUSH_MARGIN_M`` of ``horizontal_m``, adds a push away; while another drone is that close horizontally,
it stops a climb or descent that would bring the two within ``vertical_m``. A drone that climbs or descends onto
this one's height (an autopilot's RTL landing through the layers below it, which no shield steers) counts as not
separated by height while it does. Each drone shields itself, so two closing drones both stop closing.

Take-off and landing are kept apart by the launch points (``separation_m`` apart, checked when the mission file is
read); the way home is flown by the runner on the drone's layer, through the shield, and the autopilot's RTL takes
over only above the drone's home, once no drone below is in its column, where it descends and lands
(``autonomy.search_loop``).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

from autonomy.search_pilot import DecisionSource
from autonomy.setpoints import VelocityCommand
from missions.fleet import Fleet

PUSH_MPS = 2.0
"""Speed (m/s) added away from a drone that is within ``PUSH_MARGIN_M`` of the horizontal separation."""
PUSH_MARGIN_M = 5.0
"""The push starts this far (m) outside the horizontal separation: a drone sliding past another (its closing
velocity taken out, its velocity along the other's bearing kept) settles outside the separation, not on its edge."""
VERTICAL_LOOKAHEAD_S = 10.0
"""A drone climbing or descending onto another's height within this many seconds is not separated by height from
it: the other keeps its horizontal distance while it passes (long enough to stop short of it at full speed)."""
AIRBORNE_M = 1.0
"""Height above its home (m) above which a drone counts as flying (on the ground, separation does not apply)."""


@dataclass(frozen=True)
class Separation:
    """The separation rule of a fleet (module docstring)."""

    horizontal_m: float
    vertical_m: float
    """0: height never separates (a fleet flown on one layer)."""
    lookahead_s: float = 2.0
    """The shield acts this many seconds of closing flight before the horizontal separation."""

    @classmethod
    def of(cls, fleet: Fleet) -> Separation:
        return cls(fleet.separation_m, fleet.altitude_layer_m / 2.0)

    def separated(self, a: Position, b: Position) -> bool:
        return (math.hypot(a.north_m - b.north_m, a.east_m - b.east_m) >= self.horizontal_m
                or abs(a.up_m - b.up_m) >= self.vertical_m > 0.0)


class Position(NamedTuple):
    """Where a drone is (mission frame: metres north, east and up from the mission's home) and how it moves (a
    tuple: every runner makes one for every drone on every tick)."""

    name: str
    north_m: float
    east_m: float
    up_m: float
    vn_mps: float = 0.0
    ve_mps: float = 0.0
    vup_mps: float = 0.0
    """Climb rate (m/s, up positive)."""
    airborne: bool = True


@dataclass
class FleetPlace:
    """What a runner flying in a fleet is given: its name, its seat in the fleet's decision rounds, its row of the
    shared search state, the separation rule, and where the other drones are."""

    name: str
    row: int
    seat: DecisionSource
    rule: Separation
    others: Callable[[], list[Position]]
    """The other drones, as their runners see them now (filtered positions)."""
    shielded: int = field(default=0, init=False)
    """Setpoints the shield changed."""


def separated_velocity(own: Position, command: VelocityCommand, others: list[Position], rule: Separation,
                       max_speed_mps: float) -> VelocityCommand:
    """``command`` with what would close on a drone that is not separated taken out (module docstring)."""
    vn, ve, vd = command.vn, command.ve, command.vd
    guard_m = rule.horizontal_m + rule.lookahead_s * max_speed_mps
    for other in others:
        if not other.airborne:
            continue
        dn, de = own.north_m - other.north_m, own.east_m - other.east_m
        distance = math.hypot(dn, de)
        if distance >= guard_m:
            continue
        vertical_gap = abs(own.up_m - other.up_m)
        if rule.vertical_m > 0.0 and vertical_gap >= rule.vertical_m and not _coming_onto(own, other, rule):
            # separated by height: keep it so (no climb or descent towards the other's height)
            towards = -vd if other.up_m > own.up_m else vd  # up is -vd
            if towards > 0.0 and vertical_gap - towards * rule.lookahead_s < rule.vertical_m:
                vd = 0.0
            continue
        if distance < 1e-6:
            dn, de, distance = 1.0, 0.0, 1.0  # on top of each other: any way out
        un, ue = dn / distance, de / distance  # away from the other
        along = vn * un + ve * ue
        if along < 0.0:  # closing: take that part out
            vn, ve = vn - along * un, ve - along * ue
        if distance < rule.horizontal_m + PUSH_MARGIN_M:
            vn, ve = vn + PUSH_MPS * un, ve + PUSH_MPS * ue
    return VelocityCommand(vn, ve, vd)


def _coming_onto(own: Position, other: Position, rule: Separation) -> bool:
    """Whether ``other`` climbs or descends towards ``own``'s height fast enough to be within ``vertical_m`` of it
    in ``VERTICAL_LOOKAHEAD_S`` (a drone landing or climbing through a layer: an autopilot's RTL, not shielded)."""
    above = other.up_m - own.up_m
    towards = -other.vup_mps if above > 0.0 else other.vup_mps
    return towards > 0.0 and abs(above) - towards * VERTICAL_LOOKAHEAD_S < rule.vertical_m


class SeparationWatch:
    """The closest approach of a fleet's drones, from where they are (the simulator's truth in a replay): the
    report's ``separation`` section. Call :meth:`observe` every tick."""

    def __init__(self, rule: Separation):
        self.rule = rule
        self.closest_m = math.inf
        """The smallest horizontal distance between two flying drones not separated by height."""
        self.breaches: list[dict] = []
        self._in_breach: set[tuple[str, str]] = set()

    def observe(self, now_s: float, positions: list[Position]) -> None:
        for a, b in itertools.combinations(positions, 2):
            if not (a.airborne and b.airborne):
                continue
            pair = (a.name, b.name)
            if self.rule.vertical_m == 0.0 or abs(a.up_m - b.up_m) < self.rule.vertical_m:
                self.closest_m = min(self.closest_m, math.hypot(a.north_m - b.north_m, a.east_m - b.east_m))
            if self.rule.separated(a, b):
                self._in_breach.discard(pair)
            elif pair not in self._in_breach:
                self._in_breach.add(pair)
                self.breaches.append({"time_s": round(now_s, 3), "drones": list(pair),
                                      "horizontal_m": round(math.hypot(a.north_m - b.north_m, a.east_m - b.east_m), 2),
                                      "vertical_m": round(abs(a.up_m - b.up_m), 2)})

    def summary(self) -> dict:
        return {"horizontal_m": self.rule.horizontal_m, "vertical_m": self.rule.vertical_m,
                "closest_unlayered_m": None if math.isinf(self.closest_m) else round(self.closest_m, 2),
                "breaches": self.breaches, "breached": bool(self.breaches)}
