"""Scripted searchers fly through the mission runner (``hrlsac mission run|replay --pilot NAME``): the same search
pilot, safety and report as a policy artifact, and for the same flight the same actions as in the environment.
The pilot over real UDP in real time: tests/test_runner_udp.py."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from cli_harness import assert_clean_error, run_cli

from autonomy.pilots import PilotChoice, ScriptedPilot
from autonomy.search_pilot import SearchPilot
from missions.mission import Mission
from missions.scenario import Scenario, SearchArea, Target
from missions.searchers import TUNED, make_searcher

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "missions" / "library" / "demo.yaml"


@pytest.mark.parametrize("name", ["greedy_bayes", "lookahead_bayes", "expanding_square", "parallel_track", "random"])
def test_a_scripted_pilot_acts_as_its_searcher_does_in_the_environment(name):
    """Fed the environment's positions, the pilot's searcher sees the same search state as the environment's and
    answers with the same action, value for value, until the search ends the same way."""
    from policies.env.core import SarSearchConfig
    from policies.env.tasks import make_batch

    scenario = Scenario(area=SearchArea(-50.0, 950.0, -500.0, 500.0), datum_north_m=300.0, datum_east_m=50.0,
                        datum_sigma_m=60.0, endurance_s=500.0, name="shared",
                        targets=(Target("person", 330.0, 80.0, primary=True), Target("boat", 280.0, -60.0)))
    env = make_batch(SarSearchConfig(scenarios=(scenario,), goal_conditioned=False), [7])
    searcher = make_searcher(name, env, seed=7)
    pilot = SearchPilot(Mission(scenario=scenario), ScriptedPilot(name), seed=7, bingo_failsafe_s=None)
    for step in range(600):
        decision = pilot.decide(env.position[0].copy())
        action = searcher.act()
        np.testing.assert_array_equal(np.array(decision.action), action[0].astype(np.float64), err_msg=f"step {step}")
        if decision.end is not None:
            break
        _, _, terminated, truncated, info = env.step(action)
        assert not truncated[0]
    else:
        raise AssertionError("the search did not end within 600 steps")
    # the environment ended the same step, for the same reason
    ended = {"victim reached": info["success"][0], "returned home": info["returned"][0],
             "endurance exhausted": info["ran_dry"][0]}
    assert terminated[0] and decision.end in ended and ended[decision.end]
    assert step > 20  # a search, not an immediate end


def test_the_replay_names_the_pilot_and_flies_it_like_a_policy(tmp_path):
    """``mission replay --pilot``: the report names the pilot and its settings; the vehicle takes off, searches,
    confirms the victim with a close look (the camera zoomed in), returns and lands; two replays are identical."""
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        result = run_cli("mission", "replay", str(DEMO), "--pilot", "lookahead_bayes", "--out", str(out),
                         "--no-video", "--quiet")
        assert result.code == 0, result.err
        assert "demo (lookahead_bayes): 1/1 searches found the victim" in result.out
    report = json.loads((outs[0] / "report.json").read_text())
    assert report["pilot"] == "lookahead_bayes" and "policy" not in report
    assert report["pilot_settings"] == dataclasses.asdict(TUNED["lookahead_bayes"])
    assert report["success"] and report["search_end"] == "victim reached" and report["victim_confirmed"]
    assert report["outcome"]["outcome"] == "completed" and report["outcome"]["vehicle_end"] == "landed and disarmed"
    assert report["setpoints_sent"] > 20 * report["steps"]  # the stream at 20 Hz or more through the search
    assert (outs[0] / "flight.tlog").read_bytes() == (outs[1] / "flight.tlog").read_bytes()
    assert (outs[0] / "report.json").read_text() == (outs[1] / "report.json").read_text()


def test_a_policy_artifacts_report_names_its_algorithm_as_the_pilot(tmp_path):
    policy = ROOT / "policies" / "pretrained" / "hrl-sac.pt"
    result = run_cli("mission", "replay", str(DEMO), "--policy", str(policy), "--out", str(tmp_path), "--no-video",
                     "--quiet")
    assert result.code == 0, result.err
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["pilot"] == "hrl-sac" and report["policy"] == str(policy) and len(report["policy_sha256"]) == 64


@pytest.mark.parametrize("args, mentions", [
    (["--pilot", "nope"], ["--pilot: no scripted searcher 'nope'; choose from random, expanding_square"]),
    (["--pilot", "greedy_bayes", "--policy", "p.pt"], ["not allowed with argument"]),
    ([], ["one of the arguments --policy --pilot is required"]),
])
def test_a_bad_pilot_is_one_line(args, mentions, tmp_path):
    for command in ("replay", "run"):
        extra = ["--connect", "udpin:127.0.0.1:0"] if command == "run" else []
        result = run_cli("mission", command, str(DEMO), *args, *extra, "--out", str(tmp_path / command))
        assert_clean_error(result, *mentions)
        assert not (tmp_path / command).exists()


def test_a_pilot_choice_is_exactly_one_of_an_artifact_and_a_searcher():
    with pytest.raises(ValueError, match="give exactly one of --policy FILE and --pilot NAME"):
        PilotChoice()
    with pytest.raises(ValueError, match="give exactly one of --policy FILE and --pilot NAME"):
        PilotChoice(policy="p.pt", scripted="greedy_bayes")
    pilot = PilotChoice(scripted="greedy_bayes").load()
    assert isinstance(pilot, ScriptedPilot) and pilot.describe()["pilot"] == "greedy_bayes"
    with pytest.raises(RuntimeError, match="before attach"):
        pilot.act(np.zeros(288))
