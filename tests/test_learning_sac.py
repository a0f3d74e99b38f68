"""Flat SAC measurably beats its untrained self on an easy mission: tests/easy_missions.py's check (the task,
budget and what "learned" means), in a file apart from HRL-SAC's (tests/test_learning.py) so that pytest-xdist's
``--dist loadfile`` (the Makefile's) trains the two agents on two workers: each run is one of the suite's longest
tests, and together in one file they were its longest stretch."""
from __future__ import annotations

import pytest
from easy_missions import check_learns

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_flat_sac_beats_its_untrained_self_on_an_easy_mission(tmp_path):
    check_learns(tmp_path, "sac")
