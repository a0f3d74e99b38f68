"""The two walkthroughs of docs/architecture.md stay true: each step is told in at most six files, and every file
the page names (on the path or called by name) exists, so that a move or a rename cannot leave the page behind."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "architecture.md").read_text()
PATH = re.compile(r"`((?:autonomy|missions|policies|simulation|sitl_bridge)/[\w/]+\.py)")


def section(title: str) -> str:
    start = PAGE.index(f"## {title}\n")
    end = PAGE.find("\n## ", start + 1)
    return PAGE[start:end if end > 0 else None]


def step_files(text: str) -> list[str]:
    """The file each numbered item of the walkthrough starts with (the file the step is in there)."""
    return [PATH.search(item).group(1) for item in re.findall(r"^\d+\. (.*)$", text, re.M)]


@pytest.mark.parametrize("title", ["One flight control step", "One training step"])
def test_each_walkthrough_is_at_most_six_files_that_exist(title):
    text = section(title)
    files = step_files(text)
    assert 1 <= len(set(files)) <= 6, files
    named = set(PATH.findall(text))
    missing = sorted(path for path in named if not (ROOT / path).is_file())
    assert not missing, f"docs/architecture.md ({title}) names files that do not exist: {missing}"
    assert set(files) <= named


def test_the_flight_walkthrough_names_the_functions_it_follows():
    """The calls the flight step is told by, where the page says they are."""
    from autonomy.estimator import PoseEstimator
    from autonomy.policy import Policy
    from autonomy.runner import MissionRunner
    from autonomy.search_pilot import DecisionWorker, SearchPilot
    from autonomy.vehicle_time import receive_telemetry
    from missions.goals import goal_due

    for owner, name in ((MissionRunner, "_search"), (MissionRunner, "_apply"), (MissionRunner, "tick"),
                        (PoseEstimator, "predict_to"), (SearchPilot, "decide"), (DecisionWorker, "submit"),
                        (Policy, "select_goal"), (Policy, "act")):
        assert callable(getattr(owner, name)), f"{owner.__name__}.{name}"
    assert callable(receive_telemetry) and goal_due(60, 30) and not goal_due(61, 30)
