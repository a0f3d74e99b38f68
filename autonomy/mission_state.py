"""The states of the mission runner (``autonomy.runner``), named as its report and its log lines spell them.

    CONNECT -> PREFLIGHT -> ARM -> TAKEOFF -> OFFBOARD -> SEARCH -> RTL -> LAND -> DONE
                                                     (any failure or failsafe -> RTL, or DONE with the reason)
                                      SEARCH -> OFFBOARD -> SEARCH   (resumed after the vehicle's link-loss failsafe)

OFFBOARD is the autopilot's companion mode: PX4's OFFBOARD or ArduPilot's GUIDED.
"""
from __future__ import annotations

import enum


class MissionState(enum.StrEnum):
    """One state of the runner; its value is the name written to report.json and printed."""

    CONNECT = "CONNECT"
    """Waiting for the vehicle's first autopilot HEARTBEAT."""
    PREFLIGHT = "PREFLIGHT"
    """Telemetry, home and the autopilot's parameters: the checks before arming."""
    ARM = "ARM"
    TAKEOFF = "TAKEOFF"
    """Armed, climbing to the search altitude."""
    OFFBOARD = "OFFBOARD"
    """Streaming setpoints ahead of the companion mode, then asking for it."""
    SEARCH = "SEARCH"
    """The policy flies the search."""
    RTL = "RTL"
    LAND = "LAND"
    """Returning and landing: waiting for the vehicle to disarm."""
    DONE = "DONE"


AIRBORNE_STATES = (MissionState.TAKEOFF, MissionState.OFFBOARD, MissionState.SEARCH)
"""States in which the vehicle may be flying: an abort from one of them returns home."""
COMPANION_STATES = (MissionState.OFFBOARD, MissionState.SEARCH)
"""States in which the companion computer flies the vehicle (and probes that the vehicle hears it)."""
