"""HRL-SAC measurably beats its untrained self on an easy mission (a short real training run; flat SAC's:
tests/test_learning_sac.py). The missions, the budget and what "learned" means: tests/easy_missions.py."""
from __future__ import annotations

import pytest
from easy_missions import check_learns

# slow: on a slow, shared 2-core machine a training run can outlast the suite's default timeout (300 s)
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_hrl_sac_beats_its_untrained_self_on_an_easy_mission(tmp_path):
    check_learns(tmp_path, "hrl-sac")
