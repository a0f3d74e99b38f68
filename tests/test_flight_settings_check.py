"""A mission flown with other flight settings than the policy was trained with is refused, or flown with a warning.

Regression of the fourth defect of the flight-side issue: the artifact's observation layout was checked, but a mission
whose altitude, speed, step period, K or max_steps differ from ``manifest.training_config["flight"]`` was flown
silently (the action scale, the camera footprint and ``time_progress`` then mean something else). The commands are
the real ``hrlsac mission`` entry point with the shipped policy.
"""
from __future__ import annotations

import json

import pytest
import yaml

import hrlsac_cli
from autonomy.policy import load_policy
from autonomy.preflight import flight_mismatches
from missions.mission import FlightSettings

PRETRAINED = "policies/pretrained/hrl-sac.pt"
DEMO = "missions/library/demo.yaml"


def demo_with(tmp_path, **flight) -> str:
    data = yaml.safe_load(open(DEMO))
    data["flight"].update(flight)
    path = tmp_path / "changed.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


@pytest.mark.parametrize("command", [["replay"], ["run", "--connect", "udpin:127.0.0.1:9"]])
def test_a_mission_at_another_altitude_is_refused_before_flying(tmp_path, capsys, command):
    mission = demo_with(tmp_path, altitude_m=40)
    code = hrlsac_cli.main(["mission", command[0], mission, "--policy", PRETRAINED, "--out", str(tmp_path / "out"),
                             *command[1:]])
    assert code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == (f"hrlsac mission {command[0]}: error: {mission}: flight settings differ from the policy's training "
                    "(altitude_m: mission 40, trained 50): change the mission's flight block, or pass "
                    "--accept-flight-mismatch to fly it anyway")
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_every_differing_setting_is_named():
    trained = load_policy(PRETRAINED).manifest.training_config
    flight = FlightSettings(altitude_m=30.0, max_speed_mps=6.0, step_period_s=0.5, subgoal_interval=10, max_steps=500,
                            reach_radius_m=trained["flight"]["reach_radius_m"])
    assert flight_mismatches(flight, trained) == [
        "altitude_m: mission 30, trained 50", "max_speed_mps: mission 6, trained 10",
        "step_period_s: mission 0.5, trained 1", "subgoal_interval: mission 10, trained 30",
        "max_steps: mission 500, trained 1000"]
    assert flight_mismatches(FlightSettings(**trained["flight"]), trained) == []
    assert flight_mismatches(flight, {}) == []  # an artifact that does not record them: nothing to compare


def test_with_the_flag_the_mission_flies_and_the_warning_names_the_difference(tmp_path, capsys):
    mission = demo_with(tmp_path, max_steps=80)
    code = hrlsac_cli.main(["mission", "replay", mission, "--policy", PRETRAINED, "--out", str(tmp_path / "out"),
                            "--no-video", "--quiet", "--accept-flight-mismatch"])
    assert code == 0
    err = capsys.readouterr().err
    assert (f"warning: {mission}: flying with flight settings the policy was not trained with "
            "(max_steps: mission 80, trained 1000)") in err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["steps"] <= 80 and report["complete"] is True
