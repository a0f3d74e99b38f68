"""The crew's map is calibrated (``missions.belief``, ``benchmarks/map_calibration.py``): a look lowers each cell by
the detection probability averaged over the part of the cell inside the footprint (checked against a brute-force
lattice of the camera's point model), leaves the cells it misses alone, the map's cells stay at most
``MAP_CELL_M`` across whatever the area (and the observation still sees a 16 x 16 summary), drift and blur keep the
mass on a finer map, and on the 2 km square what the map expects to be found is what is found."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from map_calibration import fly  # noqa: E402

from autonomy.observation import LAYOUT_V4  # noqa: E402
from missions import belief, search  # noqa: E402
from missions.coverage import GRID_SIZE, OBS_GRID, downsample_coverage  # noqa: E402
from missions.mission import FlightSettings  # noqa: E402
from missions.scenario import Conditions, Scenario, SearchArea, Target  # noqa: E402
from missions.search import ScenarioBatch  # noqa: E402
from missions.search_state_v1 import TARGET_SLOTS, BeliefSearchState  # noqa: E402
from policies.cli.evaluate import read_generator_config  # noqa: E402
from policies.env.core import SarSearchConfig  # noqa: E402
from policies.env.tasks import make_batch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TWO_KM = np.array([[0.0, 2000.0, -1000.0, 1000.0]])
SIZE_M, FACTOR = np.array([0.5]), np.array([0.7])


def lattice_mean(drone, north_low, east_low, cell_m, altitude, zoom, points=400):
    """Brute force: the camera's point model averaged over a points x points lattice of the cell (its midpoints)."""
    fractions = (np.arange(points) + 0.5) / points
    north, east = np.meshgrid(north_low + fractions * cell_m[0], east_low + fractions * cell_m[1], indexing="ij")
    where = np.stack([north.ravel(), east.ravel()], axis=1)[None]
    p = search.detection_probability_from_factors(np.array([drone]), where, np.full((1, len(where[0])), SIZE_M[0]),
                                                  np.full((1, len(where[0])), FACTOR[0]), np.array([altitude]),
                                                  np.array([zoom]), np.array([1.0]))
    return float(p.mean())


def map_for(area=TWO_KM):
    cells = belief.map_cells(area)
    return np.full((1, cells, cells), 1.0 / cells ** 2), np.zeros((1, cells, cells)), cells


@pytest.mark.parametrize("altitude, zoom", [(50.0, 0.0), (50.0, 0.3), (20.0, 0.5)])
def test_a_look_lowers_each_cell_by_the_detection_probability_averaged_over_its_covered_part(altitude, zoom):
    grid, searched, cells = map_for()
    offset = np.array([[7.3, -12.1]])  # a drifted map: its cells are read where their water is now
    drone = np.array([1013.7, 4.2])
    before = grid.copy()
    removed = belief.look(grid, searched, TWO_KM, offset, drone[None], np.array([altitude]), np.array([zoom]),
                          np.array([1.0]), SIZE_M, FACTOR)
    cell_m = belief.cell_size_m(TWO_KM, cells)[0]
    corner = TWO_KM[0, 0::2] + offset[0]
    half_width = float(search.footprint_half_width_m(altitude, zoom))
    own = ((drone - corner) // cell_m).astype(int)
    reach = int(math.ceil(half_width / cell_m.min())) + 1
    partial = 0
    for row in range(own[0] - reach, own[0] + reach + 1):
        for col in range(own[1] - reach, own[1] + reach + 1):
            low = corner + (row, col) * cell_m
            expected = lattice_mean(drone, low[0], low[1], cell_m, altitude, zoom)
            covered = np.clip(np.minimum(low + cell_m, drone + half_width) - np.maximum(low, drone - half_width), 0,
                              None).prod() / cell_m.prod()
            partial += 0.0 < covered < 1.0
            assert 1.0 - grid[0, row, col] / before[0, row, col] == pytest.approx(expected, abs=2e-3)
            assert searched[0, row, col] == pytest.approx(1.0 - grid[0, row, col] / before[0, row, col])
    assert partial >= 1  # the footprint cuts through cells: a look at the cell centres would be off there
    assert removed[0] == pytest.approx((before - grid).sum())


def test_a_look_whose_footprint_misses_a_cell_leaves_it_unchanged():
    grid, searched, cells = map_for()
    cell_m = belief.cell_size_m(TWO_KM, cells)[0]
    half_width = float(search.footprint_half_width_m(50.0, 0.0))
    drone = np.array([20 * cell_m[0] + half_width + 1e-6, 5.0])  # the footprint's south edge on a cell boundary
    before = grid.copy()
    belief.look(grid, searched, TWO_KM, np.zeros((1, 2)), drone[None], np.array([50.0]), np.array([0.0]),
                np.array([1.0]), SIZE_M, FACTOR)
    east_low = TWO_KM[0, 2] + np.arange(cells) * cell_m[1]
    east_missed = (east_low + cell_m[1] <= drone[1] - half_width - 1e-6) | (east_low >= drone[1] + half_width + 1e-6)
    north_low = TWO_KM[0, 0] + np.arange(cells) * cell_m[0]
    north_missed = (north_low + cell_m[0] <= 20 * cell_m[0]) | (north_low >= drone[0] + half_width + 1e-6)
    missed = north_missed[:, None] | east_missed[None, :]
    assert np.array_equal(grid[0][missed], before[0][missed]) and not searched[0][missed].any()
    assert (grid[0][~missed] < before[0][~missed]).all()  # every cell it does touch lost some
    assert (~missed[19]).sum() == 0 and (~missed[20]).sum() > 0  # the row south of the edge untouched, the next not


def test_the_map_keeps_its_cells_at_most_map_cell_m_across_whatever_the_area():
    for side_m, cells in ((1000.0, 32), (750.0, 32), (1500.0, 48), (2000.0, 64), (5000.0, 160)):
        area = np.array([[0.0, side_m, -side_m / 2.0, side_m / 2.0]])
        assert belief.map_cells(area) == cells
        assert belief.cell_size_m(area, cells).max() <= belief.MAP_CELL_M + 1e-9
    rectangle = np.array([[0.0, 1000.0, 0.0, 750.0], [0.0, 2000.0, 0.0, 300.0]])  # the largest side of any decides
    assert belief.map_cells(rectangle) == 64
    assert belief.map_cells(rectangle[0]) == GRID_SIZE


def test_the_summary_of_a_finer_map_is_the_mean_of_its_blocks():
    rng = np.random.default_rng(3)
    for cells in (32, 48, 64):
        grid = rng.random((2, cells, cells))
        side = cells // OBS_GRID
        expected = grid.reshape(2, OBS_GRID, side, OBS_GRID, side).mean(axis=(2, 4)).reshape(2, -1)
        np.testing.assert_allclose(downsample_coverage(grid), expected, rtol=1e-6)


def test_a_2km_search_flies_a_64_cell_map_and_the_observation_still_sees_its_16_x_16_summary():
    large = read_generator_config(str(ROOT / "docs" / "results" / "large-area.yaml"))
    core = make_batch(SarSearchConfig(split="val", pool_size=4, generator=large), [0, 1, 2, 3])
    assert core.belief.shape == (4, 64, 64) and core.coverage.shape == (4, 64, 64)
    blocks = core.belief.reshape(4, OBS_GRID, 4, OBS_GRID, 4).mean(axis=(2, 4)).reshape(4, -1)
    summary = core.obs[:, LAYOUT_V4.by_name["belief"].slice]
    np.testing.assert_allclose(summary, np.minimum(blocks / core.prior_peak[:, None], 1.0), rtol=1e-6, atol=1e-7)
    core.coverage[:] = 1.0
    np.testing.assert_allclose(core.searched_cells, GRID_SIZE ** 2)  # the coverage bonus counts default-grid cells
    # the flight pilot's state, built from a mission's scenario, sizes its map from the same rule
    pilot = BeliefSearchState(ScenarioBatch.from_scenarios([core.scenarios[0]], num_targets=TARGET_SLOTS),
                              FlightSettings())
    assert pilot.belief.shape == (1, 64, 64)


def test_drift_and_blur_keep_the_mass_of_a_finer_map():
    area = SearchArea(0.0, 2000.0, -1000.0, 1000.0)
    s = Scenario(area=area, datum_north_m=1000.0, datum_east_m=0.0, datum_sigma_m=150.0,
                 targets=(Target("person", 1000.0, 0.0, primary=True),), conditions=Conditions(),
                 current_north_mps=0.3, current_east_mps=-0.2, forecast_current_north_mps=0.35,
                 forecast_current_east_mps=-0.25)
    state = BeliefSearchState(ScenarioBatch.from_scenarios([s], num_targets=TARGET_SLOTS), FlightSettings())
    state.reset(np.array([0]), np.array([1], dtype=np.uint64))
    assert state.belief.shape[1] == 64 and state.belief.sum() == pytest.approx(1.0)
    start = state.belief[0].copy()
    for _ in range(200):  # sensor off: 200 s of drift (several cells) and six blurs
        state.advance(np.array([[0.0, 0.0]]), np.array([0.0]), np.array([0.0]), 1.0)
    assert state.belief.sum() == pytest.approx(1.0, rel=1e-9)
    moved = np.unravel_index(state.belief[0].argmax(), start.shape)
    assert moved != np.unravel_index(start.argmax(), start.shape)  # it did drift
    assert state.belief[0].max() < start.max()  # and spread


def test_on_the_2km_square_the_map_expects_what_is_found():
    large = read_generator_config(str(ROOT / "docs" / "results" / "large-area.yaml"))
    figures = fly("greedy_bayes", large, "val", 100, None, particles=100)
    assert figures["map_cells"] == 64
    # Against the sightings themselves: noisy (the standard error is about 5 points at 100 sorties), so only a gross
    # error (a look counted twice, a hazard summed past the first sighting) fails this.
    assert abs(figures["residual"]) < 3.0 * figures["se"]
    # Against the Monte Carlo reference on the same looks, free of the detection draws' noise: within a point. A map
    # of 62.5 m cells looked at at their centres, or with its prior spread over the area instead of keeping its
    # tails in the edge cells, is several points above it on these sorties.
    assert abs(figures["minus_reference"]["mean"]) < 0.01


def test_the_same_sorties_give_the_same_figures():
    large = read_generator_config(str(ROOT / "docs" / "results" / "large-area.yaml"))
    first = fly("greedy_bayes", large, "val", 8, None, particles=20)
    second = fly("greedy_bayes", large, "val", 8, None, particles=20)
    first.pop("wall_s", None), second.pop("wall_s", None)
    assert first == second
