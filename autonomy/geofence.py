"""The runner's geofence guard: stop and turn back before the fence, whatever the policy commands.

The policy was trained inside the same fence, but a learned policy can still head out of it; the guard works on each
velocity command before it is streamed. Per axis of the (rectangular, local NED) fence, with a margin inside it:

* already beyond the margin: the velocity component is made to point back inside (1 m/s if it was zero);
* would cross the margin within ``lookahead_s`` at the commanded velocity: the component is cancelled;
* otherwise the command passes unchanged.
"""
from __future__ import annotations

from missions.scenario import SearchArea


def guard_velocity(vn: float, ve: float, north_m: float, east_m: float, fence: SearchArea, margin_m: float,
                   lookahead_s: float) -> tuple[float, float]:
    """(vn, ve) after the guard, for a drone at (north_m, east_m); see the module docstring."""
    guarded = []
    for v, pos, low, high in ((vn, north_m, fence.north_min_m + margin_m, fence.north_max_m - margin_m),
                              (ve, east_m, fence.east_min_m + margin_m, fence.east_max_m - margin_m)):
        if pos < low:
            v = max(v, 0.0) or 1.0  # turn back inside
        elif pos > high:
            v = min(v, 0.0) or -1.0
        elif not low <= pos + v * lookahead_s <= high:
            v = 0.0
        guarded.append(v)
    return guarded[0], guarded[1]
