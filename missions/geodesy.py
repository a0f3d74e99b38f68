"""WGS-84 conversions between geodetic coordinates and a local NED frame around a home point.

This is the single geodesy implementation of the stack: the simulated vehicle, the mission files and
the flight runtime all convert through it, so a point written in a mission file lands on the same
spot in the simulator and in flight.

Conversions go through Earth-centred, Earth-fixed (ECEF) coordinates:

* geodetic -> ECEF is the exact closed form;
* ECEF -> geodetic uses Bowring's method with two iterations, written without trigonometry inside
  the loop (better than 1e-11 deg and 1e-6 m for heights from -10 km to 100 km);
* ECEF offsets are rotated into north/east/down with the tangent-plane basis at home.

The local frame is the tangent plane at home (not a map projection): ``down`` is measured along the
home's ellipsoid normal, so a point 50 km away at ``down = 0`` is about 200 m above the ellipsoid.

Altitudes are treated as heights above the WGS-84 ellipsoid. MAVLink reports altitude above mean sea
level; the difference (the geoid undulation, under 110 m everywhere) is nearly constant over a search
area, and because every part of the stack uses this same convention, positions stay consistent.
The only effect is a horizontal scale error below 2e-5 (under 1 m at 50 km).

The hot paths (the SITL and the runner convert at 10-50 Hz) use :class:`LocalFrame`, which caches the
home's position and rotation basis so that each conversion is a handful of scalar ``math`` calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from missions.validation import FINITE, check_fields

WGS84_A_M = 6378137.0
"""Semi-major axis (equatorial radius) of the WGS-84 ellipsoid, metres."""

WGS84_F = 1 / 298.257223563
"""Flattening of the WGS-84 ellipsoid."""

WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
"""Semi-minor axis (polar radius), metres."""

WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""First eccentricity squared."""

_EP2 = WGS84_E2 / (1.0 - WGS84_E2)  # second eccentricity squared
_ONE_MINUS_F = 1.0 - WGS84_F
_ONE_MINUS_E2 = 1.0 - WGS84_E2
# Bowring's iteration converges so fast that two rounds reach the limit of double precision for
# any terrestrial or aerial point; more rounds would only cost time.
_BOWRING_ITERATIONS = 2


@dataclass(frozen=True)
class GeoPoint:
    """A WGS-84 geodetic position.

    Attributes:
        lat_deg: latitude in degrees, north positive, in [-90, 90].
        lon_deg: longitude in degrees, east positive, in [-180, 180].
        alt_m: altitude in metres (treated as height above the WGS-84 ellipsoid, see module notes).
    """

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, (("lat_deg", -90.0, 90.0), ("lon_deg", -180.0, 180.0), ("alt_m", FINITE)))


def geodetic_to_ecef(lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
    """Convert geodetic latitude/longitude (deg) and ellipsoidal height (m) to ECEF metres (exact)."""
    lat = math.radians(lat_deg)
    lon = math.radians(lon_deg)
    sin_lat = math.sin(lat)
    cos_lat = math.cos(lat)
    # Prime-vertical radius of curvature: distance from the surface to the polar axis along the normal.
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
    r = (n + alt_m) * cos_lat
    return (r * math.cos(lon), r * math.sin(lon), (n * _ONE_MINUS_E2 + alt_m) * sin_lat)


def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Convert ECEF metres to (latitude deg, longitude deg, ellipsoidal height m).

    Bowring's method: iterate on the parametric (reduced) latitude beta, starting from the value it
    would have on a sphere-scaled ellipsoid. Each round only needs sin/cos of beta, which follow
    algebraically from tan(beta) = (1 - f) tan(lat), so the loop has no trigonometric calls.
    Valid everywhere outside a ~40 km ball around the Earth's centre, i.e. for any real vehicle.
    At the poles the longitude is undefined; ``atan2`` then returns 0 (or +-180).
    """
    p = math.hypot(x, y)  # distance from the polar axis
    # Initial reduced latitude: tan(beta0) = z / ((1 - f) p).
    sin_b, cos_b = _unit(z, _ONE_MINUS_F * p)
    lat_num = z
    lat_den = p
    for _ in range(_BOWRING_ITERATIONS):
        # tan(lat) = (z + e'^2 b sin^3 beta) / (p - e^2 a cos^3 beta)
        lat_num = z + _EP2 * WGS84_B_M * sin_b * sin_b * sin_b
        lat_den = p - WGS84_E2 * WGS84_A_M * cos_b * cos_b * cos_b
        sin_b, cos_b = _unit(_ONE_MINUS_F * lat_num, lat_den)
    sin_lat, cos_lat = _unit(lat_num, lat_den)
    # Height along the normal; this form stays accurate at the poles, unlike p / cos(lat) - N.
    alt_m = p * cos_lat + z * sin_lat - WGS84_A_M * math.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
    return (math.degrees(math.atan2(lat_num, lat_den)), math.degrees(math.atan2(y, x)), alt_m)


def _unit(num: float, den: float) -> tuple[float, float]:
    """(sin, cos) of the angle whose tangent is num / den (den is the cosine side)."""
    norm = math.hypot(num, den)
    if norm == 0.0:  # only at the Earth's centre; pick the equator rather than divide by zero
        return (0.0, 1.0)
    return (num / norm, den / norm)


class LocalFrame:
    """The north/east/down tangent frame at a geodetic home point, with its basis cached.

    Build one per home and reuse it: each conversion is then a few scalar ``math`` calls.
    """

    __slots__ = ("home", "_x0", "_y0", "_z0", "_sin_lat", "_cos_lat", "_sin_lon", "_cos_lon")

    def __init__(self, home: GeoPoint) -> None:
        """Cache the home's ECEF position and the sines/cosines that make up the NED rotation."""
        self.home = home
        self._x0, self._y0, self._z0 = geodetic_to_ecef(home.lat_deg, home.lon_deg, home.alt_m)
        lat = math.radians(home.lat_deg)
        lon = math.radians(home.lon_deg)
        self._sin_lat = math.sin(lat)
        self._cos_lat = math.cos(lat)
        self._sin_lon = math.sin(lon)
        self._cos_lon = math.cos(lon)

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """Geodetic (deg, deg, m) -> (north, east, down) metres relative to home."""
        x, y, z = geodetic_to_ecef(lat_deg, lon_deg, alt_m)
        dx = x - self._x0
        dy = y - self._y0
        dz = z - self._z0
        sl, cl, so, co = self._sin_lat, self._cos_lat, self._sin_lon, self._cos_lon
        # Rows of the ECEF -> NED rotation: the north, east and down unit vectors at home.
        horizontal = co * dx + so * dy  # component along the home meridian plane's outward axis
        north = -sl * horizontal + cl * dz
        east = -so * dx + co * dy
        down = -cl * horizontal - sl * dz
        return (north, east, down)

    def to_geodetic(self, north_m: float, east_m: float, down_m: float) -> tuple[float, float, float]:
        """(north, east, down) metres relative to home -> geodetic (lat deg, lon deg, alt m)."""
        sl, cl, so, co = self._sin_lat, self._cos_lat, self._sin_lon, self._cos_lon
        # Transpose of the rotation in to_ned (the basis is orthonormal).
        horizontal = -sl * north_m - cl * down_m
        x = self._x0 + co * horizontal - so * east_m
        y = self._y0 + so * horizontal + co * east_m
        z = self._z0 + cl * north_m - sl * down_m
        return ecef_to_geodetic(x, y, z)
