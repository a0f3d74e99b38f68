"""Tests for the WGS-84 geodesy shared by the SITL, the mission files and the flight runtime."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from missions.geodesy import (
    WGS84_A_M,
    WGS84_F,
    GeoPoint,
    LocalFrame,
    ecef_to_geodetic,
    geodetic_to_ecef,
)

E2 = WGS84_F * (2 - WGS84_F)
B_M = WGS84_A_M * (1 - WGS84_F)

HOMES = {
    "equator": GeoPoint(0.0, 0.0, 0.0),
    "47N": GeoPoint(47.3977, 8.5456, 488.0),
    "near_north_pole": GeoPoint(89.9, 30.0, 120.0),
    "near_south_pole": GeoPoint(-89.5, -120.0, 2800.0),
    "antimeridian": GeoPoint(-12.0, 179.9, 15.0),
    "southern_dead_sea": GeoPoint(-33.9, 151.2, -400.0),
}

MAX_RANGE_M = 50_000.0
ROUND_TRIP_TOL_M = 1e-3


def meridian_radius_m(lat_deg: float) -> float:
    """Textbook meridian radius of curvature M = a (1 - e^2) / (1 - e^2 sin^2 lat)^1.5."""
    s = math.sin(math.radians(lat_deg))
    return WGS84_A_M * (1 - E2) / (1 - E2 * s * s) ** 1.5


def prime_vertical_radius_m(lat_deg: float) -> float:
    """Textbook prime-vertical radius of curvature N = a / sqrt(1 - e^2 sin^2 lat)."""
    s = math.sin(math.radians(lat_deg))
    return WGS84_A_M / math.sqrt(1 - E2 * s * s)


def sample_offsets(rng: random.Random, count: int) -> list[tuple[float, float, float]]:
    """NED offsets up to 50 km away (plus the extreme compass points), altitudes -3 km to +0.5 km."""
    offsets = [
        (MAX_RANGE_M, 0.0, 0.0),
        (-MAX_RANGE_M, 0.0, 0.0),
        (0.0, MAX_RANGE_M, 0.0),
        (0.0, -MAX_RANGE_M, -3000.0),
    ]
    for _ in range(count):
        bearing = rng.uniform(-math.pi, math.pi)
        distance = MAX_RANGE_M * math.sqrt(rng.random())  # uniform over the disc
        down = rng.uniform(-3000, 500)
        offsets.append((distance * math.cos(bearing), distance * math.sin(bearing), down))
    return offsets


@pytest.mark.parametrize("home", HOMES.values(), ids=HOMES.keys())
def test_ned_geodetic_ned_round_trip_below_1_mm(home: GeoPoint) -> None:
    frame = LocalFrame(home)
    for n, e, d in sample_offsets(random.Random(7), 500):
        lat, lon, alt = frame.to_geodetic(n, e, d)
        assert -90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0
        n2, e2, d2 = frame.to_ned(lat, lon, alt)
        assert math.dist((n, e, d), (n2, e2, d2)) < ROUND_TRIP_TOL_M, (n, e, d)


@pytest.mark.parametrize("home", HOMES.values(), ids=HOMES.keys())
def test_function_api_matches_frame_and_round_trips(home: GeoPoint) -> None:
    frame = LocalFrame(home)
    for n, e, d in sample_offsets(random.Random(11), 50):
        geo = LocalFrame(home).to_geodetic(n, e, d)
        assert geo == frame.to_geodetic(n, e, d)
        assert math.dist(LocalFrame(home).to_ned(*geo), (n, e, d)) < ROUND_TRIP_TOL_M


@settings(max_examples=300, deadline=None)
@given(
    lat=st.floats(-90, 90),
    lon=st.floats(-180, 180),
    alt=st.floats(-500, 9000),
    north=st.floats(-MAX_RANGE_M, MAX_RANGE_M),
    east=st.floats(-MAX_RANGE_M, MAX_RANGE_M),
    down=st.floats(-5000, 500),
)
def test_round_trip_property_anywhere_on_earth(
    lat: float, lon: float, alt: float, north: float, east: float, down: float
) -> None:
    home = GeoPoint(lat, lon, alt)
    geo = LocalFrame(home).to_geodetic(north, east, down)
    assert math.dist(LocalFrame(home).to_ned(*geo), (north, east, down)) < ROUND_TRIP_TOL_M


def test_home_maps_to_origin_and_back() -> None:
    for home in HOMES.values():
        assert max(abs(v) for v in LocalFrame(home).to_ned(home.lat_deg, home.lon_deg, home.alt_m)) < 1e-6
        lat, lon, alt = LocalFrame(home).to_geodetic(0.0, 0.0, 0.0)
        assert lat == pytest.approx(home.lat_deg, abs=1e-12)
        assert alt == pytest.approx(home.alt_m, abs=1e-6)
        if abs(home.lat_deg) < 89.99:  # longitude is ill-conditioned right at the pole
            assert lon == pytest.approx(home.lon_deg, abs=1e-12)


def test_antimeridian_crossing_20_km_east() -> None:
    home = GeoPoint(-12.0, 179.9, 15.0)
    lat, lon, alt = LocalFrame(home).to_geodetic(0.0, 20_000.0, 0.0)
    # 20 km east of 179.9 E is past 180: longitude wraps to the western hemisphere.
    parallel_radius = prime_vertical_radius_m(home.lat_deg) * math.cos(math.radians(home.lat_deg))
    expected_dlon = math.degrees(20_000.0 / parallel_radius)
    assert lon < 0.0
    assert lon == pytest.approx(179.9 + expected_dlon - 360.0, abs=1e-4)
    assert math.dist(LocalFrame(home).to_ned(lat, lon, alt), (0.0, 20_000.0, 0.0)) < ROUND_TRIP_TOL_M
    # Either spelling of the same longitude gives the same local position.
    assert math.dist(LocalFrame(home).to_ned(lat, lon + 360.0, alt), (0.0, 20_000.0, 0.0)) < ROUND_TRIP_TOL_M


def test_geodetic_ecef_round_trip_precision() -> None:
    rng = random.Random(3)
    points = [(90.0, 0.0, 0.0), (-90.0, 0.0, 100.0), (0.0, 180.0, 0.0), (0.0, -180.0, -10_000.0)]
    points += [(rng.uniform(-90, 90), rng.uniform(-180, 180), rng.uniform(-10_000, 100_000)) for _ in range(5000)]
    for lat, lon, alt in points:
        lat2, lon2, alt2 = ecef_to_geodetic(*geodetic_to_ecef(lat, lon, alt))
        assert abs(lat2 - lat) < 1e-9
        assert abs(alt2 - alt) < 1e-3
        if abs(lat) < 89.99:
            dlon = (lon2 - lon + 180.0) % 360.0 - 180.0  # +180 and -180 are the same meridian
            assert abs(dlon) < 1e-9


def test_ecef_known_values() -> None:
    assert geodetic_to_ecef(0.0, 0.0, 0.0) == pytest.approx((WGS84_A_M, 0.0, 0.0), abs=1e-9)
    assert geodetic_to_ecef(0.0, 90.0, 10.0) == pytest.approx((0.0, WGS84_A_M + 10.0, 0.0), abs=1e-6)
    assert geodetic_to_ecef(90.0, 0.0, 0.0) == pytest.approx((0.0, 0.0, B_M), abs=1e-6)
    lat, _, alt = ecef_to_geodetic(0.0, 0.0, -B_M - 5.0)
    assert lat == pytest.approx(-90.0, abs=1e-12)
    assert alt == pytest.approx(5.0, abs=1e-6)


@pytest.mark.parametrize(("lat_deg", "metres_per_degree"), [(0.0, 110_574.0), (45.0, 111_132.0)])
def test_length_of_one_degree_of_latitude(lat_deg: float, metres_per_degree: float) -> None:
    # Published WGS-84 values, rounded to the metre (the series 111132.954 - 559.822 cos 2lat
    # + 1.175 cos 4lat gives 110574.3 and 111131.8). Measure over +-0.0005 deg so that the
    # tangent-plane projection differs from the arc length by nanometres.
    home = GeoPoint(lat_deg, 10.0, 0.0)
    north_hi = LocalFrame(home).to_ned(lat_deg + 0.0005, 10.0, 0.0)[0]
    north_lo = LocalFrame(home).to_ned(lat_deg - 0.0005, 10.0, 0.0)[0]
    assert (north_hi - north_lo) / 0.001 == pytest.approx(metres_per_degree, abs=1.0)


@pytest.mark.parametrize("home", HOMES.values(), ids=HOMES.keys())
def test_one_metre_steps_follow_radii_of_curvature(home: GeoPoint) -> None:
    lat, lon, _ = LocalFrame(home).to_geodetic(1.0, 0.0, 0.0)
    expected_dlat = math.degrees(1.0 / (meridian_radius_m(home.lat_deg) + home.alt_m))
    assert lat - home.lat_deg == pytest.approx(expected_dlat, rel=1e-6)
    if abs(home.lat_deg) < 89.99:
        assert lon == pytest.approx(home.lon_deg, abs=1e-12)
        _, lon_e, _ = LocalFrame(home).to_geodetic(0.0, 1.0, 0.0)
        normal_radius = prime_vertical_radius_m(home.lat_deg) + home.alt_m
        parallel_radius = normal_radius * math.cos(math.radians(home.lat_deg))
        assert lon_e - home.lon_deg == pytest.approx(math.degrees(1.0 / parallel_radius), rel=1e-6)


@pytest.mark.parametrize("home", HOMES.values(), ids=HOMES.keys())
def test_down_is_minus_up(home: GeoPoint) -> None:
    lat, lon, alt = LocalFrame(home).to_geodetic(0.0, 0.0, -100.0)
    assert alt == pytest.approx(home.alt_m + 100.0, abs=1e-6)
    assert lat == pytest.approx(home.lat_deg, abs=1e-10)
    north, east, down = LocalFrame(home).to_ned(home.lat_deg, home.lon_deg, home.alt_m + 250.0)
    assert down == pytest.approx(-250.0, abs=1e-6)
    assert abs(north) < 1e-6 and abs(east) < 1e-6


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"lat_deg": 90.0001, "lon_deg": 0.0}, "lat_deg"),
        ({"lat_deg": -91.0, "lon_deg": 0.0}, "lat_deg"),
        ({"lat_deg": math.nan, "lon_deg": 0.0}, "lat_deg"),
        ({"lat_deg": "47.0", "lon_deg": 0.0}, "lat_deg"),
        ({"lat_deg": 0.0, "lon_deg": 180.5}, "lon_deg"),
        ({"lat_deg": 0.0, "lon_deg": -math.inf}, "lon_deg"),
        ({"lat_deg": 0.0, "lon_deg": 0.0, "alt_m": math.inf}, "alt_m"),
        ({"lat_deg": 0.0, "lon_deg": 0.0, "alt_m": math.nan}, "alt_m"),
    ],
)
def test_invalid_geopoint_fields_are_rejected_by_name(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(ValueError, match=field):
        GeoPoint(**kwargs)  # type: ignore[arg-type]


def test_geopoint_range_limits_are_inclusive() -> None:
    GeoPoint(90.0, 180.0, -420.0)
    GeoPoint(-90.0, -180.0)
    with pytest.raises(ValueError, match=r"\[-90, 90\]"):
        GeoPoint(100.0, 0.0)
