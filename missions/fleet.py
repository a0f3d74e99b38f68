"""A fleet: several drones flying one search, each from its own launch point, kept apart.

A mission file with a ``fleet`` section is a fleet mission: one search area, datum and set of objects (the
``scenario``), flown by several drones that share one crew map. The section names the drones' launch points,
either one by one or as a count on a launch line, and how they are kept apart::

    fleet:
      vehicles:                           # one launch point each, in system-id order
        - {name: alpha, north_m: 0, east_m: 0}            # name optional (drone1, drone2, ...)
        - {name: bravo, north_m: 0, east_m: 40, system_id: 7}   # system_id optional (1, 2, ...)
      separation_m: 30                    # optional (30): horizontal separation kept between drones, [5, 500]
      altitude_layer_m: 10                # optional (10): each drone searches this much above the one before, [0, 50]

or, instead of ``vehicles``, a count on a line from the scenario's ``start``, as ArduPilot's
``sim_vehicle.py --count N --auto-offset-line BEARING,DISTANCE`` spaces its instances::

    fleet:
      count: 3                            # [1, 16]
      launch_line: {bearing_deg: 90, spacing_m: 40}   # bearing from north, clockwise; spacing [5, 1000]

System ids default to 1, 2, ... as PX4 SITL numbers its instances (instance N is system N + 1) and ArduPilot's
``--auto-sysid`` does. Drone ``i`` (from 0) searches at ``flight.altitude_m + i * altitude_layer_m``, so that
drones in flight are layered in altitude as well as kept apart horizontally; take-off and landing cross the layers,
which is why the launch points themselves must be ``separation_m`` apart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from missions.mission_fields import (InvalidField, construct, field_path, read_integer, read_list, read_mapping,
                                     read_number, read_numbers, read_string)
from missions.validation import check_fields

MAX_VEHICLES = 16
"""The largest fleet a mission file may declare."""
MAX_SEARCH_ALTITUDE_M = 120.0
"""The highest layer may not search above this (the single-drone limit of ``FlightSettings.altitude_m``)."""


@dataclass(frozen=True)
class FleetVehicle:
    """One drone of a fleet: its name, MAVLink system id and launch point (metres north / east of home)."""

    name: str
    system_id: int
    """MAVLink system id, [1, 255] (SYSID_THISMAV on ArduPilot, MAV_SYS_ID on PX4)."""
    north_m: float
    east_m: float

    def __post_init__(self) -> None:
        if not self.name or not self.name.isprintable():
            raise ValueError(f"FleetVehicle.name must be a printable, non-empty name, got {self.name!r}")
        check_fields(self, (("system_id", 1, 255), ("north_m", -1e5, 1e5), ("east_m", -1e5, 1e5)),
                     integers=("system_id",))


@dataclass(frozen=True)
class Fleet:
    """The drones of a fleet mission and how they are kept apart."""

    vehicles: tuple[FleetVehicle, ...]
    separation_m: float = 30.0
    """Horizontal separation (m) the runners' shield keeps between any two drones. Allowed [5, 500]."""
    altitude_layer_m: float = 10.0
    """Altitude step (m) between the drones' search altitudes. Allowed [0, 50]."""

    def __post_init__(self) -> None:
        check_fields(self, (("separation_m", 5.0, 500.0), ("altitude_layer_m", 0.0, 50.0)))
        if not 1 <= len(self.vehicles) <= MAX_VEHICLES:
            raise ValueError(f"Fleet.vehicles must list 1 to {MAX_VEHICLES} drones, got {len(self.vehicles)}")
        for attribute in ("name", "system_id"):
            values = [getattr(vehicle, attribute) for vehicle in self.vehicles]
            repeated = sorted({value for value in values if values.count(value) > 1}, key=str)
            if repeated:
                raise ValueError(f"Fleet.vehicles must each have their own {attribute}: two have {repeated[0]}")
        for i, first in enumerate(self.vehicles):
            for second in self.vehicles[i + 1:]:
                gap = math.hypot(first.north_m - second.north_m, first.east_m - second.east_m)
                if gap < self.separation_m:
                    raise ValueError(f"Fleet.vehicles must launch at least separation_m ({self.separation_m:g} m) "
                                     f"apart: {first.name} and {second.name} are {gap:.1f} m apart; space them out")

    def search_altitude_m(self, index: int, base_altitude_m: float) -> float:
        """Search altitude of drone ``index`` (from 0) above home: its own layer above ``base_altitude_m``."""
        return base_altitude_m + index * self.altitude_layer_m


_KEYS = ("vehicles", "count", "launch_line", "separation_m", "altitude_layer_m")
_VEHICLE_KEYS = ("name", "north_m", "east_m", "system_id")


def read_fleet(value: Any, path: str, start_ne: tuple[float, float]) -> Fleet:
    """The ``fleet`` section of a mission file; ``start_ne`` is the scenario's start, where a launch line begins."""
    spec = read_mapping(value, path, _KEYS)
    listed, counted = "vehicles" in spec, "count" in spec or "launch_line" in spec
    if listed == counted:
        raise InvalidField(path, "give either 'vehicles' (a list of launch points) or 'count' with 'launch_line', "
                                 f"got {'both' if listed else 'neither'}")
    vehicles = _listed(spec["vehicles"], field_path(path, "vehicles")) if listed else _on_a_line(spec, path, start_ne)
    options = {key: read_number(spec[key], field_path(path, key)) for key in ("separation_m", "altitude_layer_m")
               if key in spec}
    return construct(Fleet, path, paths={"Fleet.vehicles": field_path(path, "vehicles")}, vehicles=vehicles,
                     **options)


def _listed(value: Any, path: str) -> tuple[FleetVehicle, ...]:
    vehicles = []
    for index, item in enumerate(read_list(value, path)):
        item_path = f"{path}[{index}]"
        spec = read_mapping(item, item_path, _VEHICLE_KEYS, required=("north_m", "east_m"))
        name = read_string(spec["name"], field_path(item_path, "name")) if "name" in spec else f"drone{index + 1}"
        system_id = (read_integer(spec["system_id"], field_path(item_path, "system_id")) if "system_id" in spec
                     else index + 1)
        vehicles.append(construct(FleetVehicle, item_path, name=name, system_id=system_id,
                                  north_m=read_number(spec["north_m"], field_path(item_path, "north_m")),
                                  east_m=read_number(spec["east_m"], field_path(item_path, "east_m"))))
    return tuple(vehicles)


def _on_a_line(spec: dict[str, Any], path: str, start_ne: tuple[float, float]) -> tuple[FleetVehicle, ...]:
    for key in ("count", "launch_line"):
        if key not in spec:
            raise InvalidField(field_path(path, key), "missing; a count of drones needs a launch line and the "
                                                      "other way round (or list 'vehicles' instead)")
    count = read_integer(spec["count"], field_path(path, "count"), 1, MAX_VEHICLES)
    line_path = field_path(path, "launch_line")
    line = read_numbers(spec["launch_line"], line_path, ("bearing_deg", "spacing_m"))
    if not -360.0 <= line["bearing_deg"] <= 360.0:
        raise InvalidField(field_path(line_path, "bearing_deg"), f"must be in [-360, 360], got {line['bearing_deg']:g}")
    if not 5.0 <= line["spacing_m"] <= 1000.0:
        raise InvalidField(field_path(line_path, "spacing_m"), f"must be in [5, 1000], got {line['spacing_m']:g}")
    bearing = math.radians(line["bearing_deg"])
    step_n, step_e = line["spacing_m"] * math.cos(bearing), line["spacing_m"] * math.sin(bearing)
    # millimetres: a bearing of 90 degrees puts the drones on the east line, not 2e-15 m north of it
    return tuple(FleetVehicle(f"drone{i + 1}", i + 1, round(start_ne[0] + i * step_n, 3),
                              round(start_ne[1] + i * step_e, 3)) for i in range(count))


def fleet_to_dict(fleet: Fleet) -> dict[str, Any]:
    """The section as plain YAML-ready data, always as a list of vehicles (a launch line is written out)."""
    return {"vehicles": [{"name": v.name, "north_m": v.north_m, "east_m": v.east_m, "system_id": v.system_id}
                         for v in fleet.vehicles],
            "separation_m": fleet.separation_m, "altitude_layer_m": fleet.altitude_layer_m}
