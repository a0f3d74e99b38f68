"""The relaxation ceiling of ``benchmarks/headroom.py`` is what its docstring says (docs/results.md, "Headroom"): its
look is the map's own look (``missions.belief.look``), it puts the camera where a look removes the most belief among
the cells the drone could reach, it looks only within its time budget, and what it sights by a time never falls as
time goes on."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from headroom import FOUND_BY_S, best_look, look_kernel, relaxation, scripted_batch  # noqa: E402

from missions import belief as belief_logic  # noqa: E402
from missions import search  # noqa: E402
from missions.generator import TASK_V1  # noqa: E402


@pytest.fixture
def core():
    return scripted_batch("val", 6, TASK_V1)


def test_the_look_kernel_is_the_maps_own_look_and_the_best_cell_is_where_the_belief_is(core):
    n, g = core.n, core.belief.shape[1]
    kernel = look_kernel(core, core.flight.altitude_m, 0.0, 1.0)
    r = kernel.shape[1] // 2
    cell = (g // 2 + 3, g // 2 - 4)
    core.belief[:] = 0.0
    core.belief[:, cell[0], cell[1]] = 1.0
    wide_and_narrow = [kernel, look_kernel(core, core.flight.altitude_m, 1.0, 1.0)]
    assert [list(v) for v in best_look(core.belief, wide_and_narrow)[:2]] == [[cell[0]] * n, [cell[1]] * n]
    allowed = np.ones_like(core.belief, dtype=bool)
    allowed[:, cell[0], cell[1]] = False  # out of reach: the best look is a neighbour whose footprint covers it
    i, j, _ = best_look(core.belief, wide_and_narrow, allowed)
    assert np.all((np.maximum(abs(i - cell[0]), abs(j - cell[1])) == 1))

    size = belief_logic.cell_size_m(core.scen.area, g)
    drone = core.scen.area[:, 0::2] + core.belief_offset + (np.array(cell) + 0.5) * size
    rows = np.arange(n)
    victim = core.scen.primary_index
    removed = belief_logic.look(core.belief, core.coverage, core.scen.area, core.belief_offset, drone,
                                np.full(n, core.flight.altitude_m), np.zeros(n), np.ones(n),
                                search.OBJECT_SIZE_M[core.scen.target_category[rows, victim]],
                                core.scen.detection_factor[rows, victim])
    np.testing.assert_allclose(removed, kernel[:, r, r], rtol=1e-12)
    assert np.all(kernel[:, r, r] > 0.0) and np.all(kernel[:, r, r] >= kernel.max(axis=(1, 2)) - 1e-15)


def test_the_relaxation_looks_within_its_budget_and_its_sightings_only_grow(core):
    result = relaxation(core)
    sighted = result["per_sortie"]
    assert np.all((sighted > 0.3) & (sighted <= 1.0))
    by_time = [result["sighted_by"][t] for t in FOUND_BY_S]
    assert by_time == sorted(by_time) and by_time[-1] <= result["expected_sighted"] + 1e-12

    later = scripted_batch("val", 6, TASK_V1)
    assert relaxation(later, reserve_s=300.0)["expected_sighted"] < result["expected_sighted"]
    never = scripted_batch("val", 6, TASK_V1)
    assert relaxation(never, reserve_s=1e5)["expected_sighted"] == 0.0
