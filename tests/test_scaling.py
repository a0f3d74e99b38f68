"""Scaling out: the worker pool, sweeps of training runs on Ray (resumable after a killed worker), and parallel
evaluation and mission replay that give exactly the serial results.

Ray runs for real here: one local instance with 2 CPUs for the whole module (the machine has 2 cores). Workers
are real processes: local ones through ``concurrent.futures`` (spawn), Ray's through its raylet; the killed
worker is a real SIGKILL of the Ray worker process training the run.
"""
from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_harness import run_cli
from hypothesis import given
from hypothesis import strategies as st

from autonomy.pilots import PilotChoice
from missions.mission import FlightSettings, Mission
from missions.mission_file import load_mission
from missions.mission_writer import save_mission
from missions.scenario import Scenario, SearchArea, Target
from policies.evaluation.parallel import evaluate_checkpoint
from policies.reports.sweep_table import DONE, FAILED, SKIPPED, ProgressTable, RunStatus, render
from policies.training.sweep import SWEEP_REPORT, check_run_folders, run_sweep
from policies.training.sweep_config import SweepFileError, load_sweep, sweep_from_dict
from simulation.parallel_replay import ReplayEpisode, replay_episodes
from simulation.worker_pool import PoolConfig, contiguous_chunks, run_tasks, start_local_ray

ray = pytest.importorskip("ray")

ROOT = Path(__file__).resolve().parents[1]
HRLSAC = [sys.executable, "-c", "import sys; from hrlsac_cli import main; sys.exit(main())"]
PRETRAINED = ROOT / "policies" / "pretrained" / "hrl-sac.pt"
NET = {"hidden": [32, 32]}
# The smallest settings of tests/training_helpers.py: 800 steps, a checkpoint every 400.
SMALL = {"num_envs": 2, "warmup_steps": 200, "batch_size": 32, "meta_batch_size": 8, "buffer_size": 5_000,
         "meta_buffer_size": 1_000, "checkpoint_every": 400, "log_every": 100, "eval_every": 0,
         "updates_per_step": 0.5, "actor": NET, "critic": NET, "meta_actor": NET, "meta_critic": NET,
         "flight": {"max_steps": 120, "subgoal_interval": 10}}
SWEEP = {"name": "tiny", "steps": 800, "algorithms": ["sac", "hrl-sac"], "seeds": [3], "set": SMALL, "retries": 0}
KILLED = "hrl-sac-default-seed3"


@pytest.fixture(scope="module")
def ray_instance():
    """One local Ray instance with 2 CPUs for every test of this module."""
    start_local_ray(num_cpus=2)
    yield ray
    ray.shutdown()


def log_rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k != "steps_per_s"} for row in csv.DictReader(handle)]


def assert_same_state(a, b, where: str = "checkpoint") -> None:
    """Deep equality of two checkpoints (tensors and arrays bit for bit; the pickled environment compared as the
    objects it holds: its pickle's bytes also depend on which equal objects happen to be shared)."""
    assert type(a) is type(b), where
    if where.endswith(".env"):
        assert_same_state(pickle.loads(a), pickle.loads(b), where + "(unpickled)")
    elif dataclasses.is_dataclass(a) or hasattr(a, "__dict__") and not isinstance(a, type):
        fields = [f.name for f in dataclasses.fields(a)] if dataclasses.is_dataclass(a) else sorted(vars(a))
        for name in fields:
            assert_same_state(getattr(a, name), getattr(b, name), f"{where}.{name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_same_state(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same_state(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), where
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, float) and np.isnan(a):
        assert np.isnan(b), where
    else:
        assert a == b, where


# ---------------------------------------------------------------------------------------------- the pool

@given(st.integers(0, 500), st.integers(1, 64))
def test_contiguous_chunks_cover_the_range_in_order_with_sizes_within_one(count, parts):
    chunks = contiguous_chunks(count, parts)
    assert [i for chunk in chunks for i in chunk] == list(range(count))
    assert len(chunks) == min(parts, count)
    if chunks:
        sizes = [len(chunk) for chunk in chunks]
        assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1


def test_pool_config_rejects_bad_options_naming_them():
    with pytest.raises(ValueError, match="--workers must be an integer in"):
        PoolConfig(workers=0)
    with pytest.raises(ValueError, match="--ray must be 'local', 'auto', 'ray://HOST:PORT'"):
        PoolConfig(ray_address="my-cluster")


def test_local_processes_return_results_in_task_order_and_re_raise_errors():
    done = []
    assert run_tasks(abs, [-3, 1, -2, 5], PoolConfig(workers=2), lambda i, r: done.append(i)) == [3, 1, 2, 5]
    assert sorted(done) == [0, 1, 2, 3]
    with pytest.raises(TypeError):
        run_tasks(abs, [-1, "not a number"], PoolConfig(workers=2))


def test_ray_without_ray_installed_is_one_clear_line(tmp_path):
    code = ("import sys; sys.modules['ray'] = None; from hrlsac_cli import main; "
            f"sys.exit(main(['evaluate', {str(tmp_path)!r}, '--ray', 'local']))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 2
    assert result.stderr.strip() == ("hrlsac evaluate: error: --ray needs Ray, which is not installed: "
                                     "pip install 'hrlsac[ray]'")


# ---------------------------------------------------------------------------------------------- sweep files

@pytest.mark.parametrize("change, field, reason", [
    ({"colour": "red"}, "colour", "unknown key; allowed: name, out, steps"),
    ({"steps": None}, "steps", "must be an integer in [1, 10000000000], got None"),
    ({"seeds": [1, 1]}, "seeds", "repeats a seed"),
    ({"algorithms": ["ppo"]}, "algorithms[0]", "must be one of hrl-sac, sac, got 'ppo'"),
    ({"grid": {"learning_rat": [0.1]}}, "grid.learning_rat", "unknown TrainConfig field 'learning_rat'"),
    ({"grid": {"flight.max_step": [100]}}, "grid.flight.max_step", "unknown TrainConfig field 'flight.max_step'"),
    ({"grid": {"seed": [1, 2]}}, "seed", "set by the sweep's own keys"),
    ({"grid": {"learning_rate": [5.0]}}, "grid", "TrainConfig.learning_rate must be a number in [1e-07, 1]"),
    ({"grid": {"learning_rate": 0.1}}, "grid.learning_rate", "must be a non-empty list"),
    ({"set": {"flight": 3}}, "set.flight", "flight is a group of fields"),
])
def test_sweep_file_errors_name_the_field(change, field, reason):
    with pytest.raises(SweepFileError) as error:
        sweep_from_dict({**SWEEP, **change}, "s.yaml")
    assert error.value.field == field and reason in error.value.reason
    assert str(error.value).startswith(f"s.yaml: {field}: ")


def test_sweep_grid_expands_every_combination_with_yaml_number_spellings(tmp_path):
    (tmp_path / "s.yaml").write_text("steps: 1000\nalgorithms: [hrl-sac, sac]\nseeds: [0, 1]\n"
                                     "grid:\n  learning_rate: [3e-4, 1.0e-3]\n  actor.hidden: [[64, 64]]\n")
    sweep = load_sweep(tmp_path / "s.yaml", out=tmp_path / "runs")
    assert len(sweep.runs) == 2 * 2 * 2
    first = sweep.runs[0]
    assert first.name == "hrl-sac-default-seed0-learning_rate=3e-4-actor.hidden=64x64"
    assert first.folder == (tmp_path / "runs" / first.name).resolve()
    assert first.config.learning_rate == 0.0003 and first.config.actor.hidden == (64, 64)
    assert [spec.config.learning_rate for spec in sweep.runs[:2]] == [0.0003, 0.001]
    assert {(spec.config.algo, spec.config.seed) for spec in sweep.runs} == {(a, s) for a in ("hrl-sac", "sac")
                                                                           for s in (0, 1)}
    (tmp_path / "bad.yaml").write_text("steps: 10\nsteps: 20\n")
    with pytest.raises(SweepFileError, match="duplicate key 'steps'"):
        load_sweep(tmp_path / "bad.yaml")


def test_progress_table_redraws_in_place_on_a_terminal_and_prints_state_changes_otherwise():
    rows = [RunStatus("a", Path("a"), 800, state=DONE, steps=800, success_rate=0.25),
            RunStatus("bb", Path("bb"), 800, state=FAILED, steps=400, message="WorkerCrashedError: died")]
    lines = render(rows)
    assert lines[1].split() == ["a", "done", "800/800", "25%"]
    assert lines[2].split()[:4] == ["bb", "failed", "400/800", "-"] and lines[2].endswith("WorkerCrashedError: died")
    assert lines[-1] == "1 done, 1 failed of 2 runs"
    live = io.StringIO()
    table = ProgressTable(live, live=True)
    table.update(rows)
    table.update(rows)
    assert live.getvalue().count(f"\x1b[{len(lines) + 1}F\x1b[J") == 1  # the table and the sweep's progress line
    assert live.getvalue().splitlines()[-1].startswith("sweep:  75%|") and "1200/1600 [" in live.getvalue()
    plain = io.StringIO()
    table = ProgressTable(plain, live=False)
    table.update(rows)
    table.update(rows)  # nothing changed: nothing printed
    assert len(plain.getvalue().splitlines()) == 2 and "\x1b" not in plain.getvalue()
    table.finish(rows)  # the whole table, then the progress line with its rate and time left
    assert plain.getvalue().splitlines()[-2:] == [lines[-1], table.meter(rows)] and "step/s" in table.meter(rows)
    quiet = io.StringIO()
    ProgressTable(quiet, live=False, enabled=False).finish(rows)
    assert quiet.getvalue() == ""


# ---------------------------------------------------------------------------------------------- sweeps

@pytest.fixture(scope="module")
def sweep_runs(ray_instance, tmp_path_factory):
    """The tiny sweep run twice: first with the HRL-SAC run's worker SIGKILLed at step 400 (no retries), then
    again to finish it. Returns the sweep, both sweeps' statuses and the first sweep's table output."""
    sweep = sweep_from_dict(SWEEP, "tiny.yaml", out=tmp_path_factory.mktemp("sweep"))
    first_output = io.StringIO()
    first = run_sweep(sweep, table=ProgressTable(first_output, live=False), refresh_s=0.2, kill_at={KILLED: 400})
    killed_checkpoint = torch.load(sweep.out / KILLED / "checkpoint.pt", weights_only=False)["step"]
    second = run_sweep(sweep, table=ProgressTable(io.StringIO(), live=False), refresh_s=0.2)
    return sweep, first, second, first_output.getvalue(), killed_checkpoint


def test_sweep_finishes_runs_skips_them_later_and_resumes_the_killed_one(sweep_runs):
    sweep, first, second, output, killed_checkpoint = sweep_runs
    states = {status.name: status for status in first}
    assert states["sac-default-seed3"].state == DONE and states["sac-default-seed3"].steps == 800
    assert states[KILLED].state == FAILED and "died" in states[KILLED].message.lower()
    assert killed_checkpoint == 400
    assert f"{KILLED}: failed" in output and "sac-default-seed3: done at 800/800 steps" in output
    again = {status.name: status for status in second}
    assert again["sac-default-seed3"].state == SKIPPED
    assert again[KILLED].state == DONE and again[KILLED].message == "resumed at step 400"
    assert again[KILLED].steps == 800
    report = json.loads((sweep.out / SWEEP_REPORT).read_text())
    assert [(run["name"], run["state"], run["steps"]) for run in report["runs"]] == [
        ("sac-default-seed3", SKIPPED, 800), (KILLED, DONE, 800)]


def test_a_resumed_sweep_run_is_the_folder_hrlsac_train_writes_uninterrupted(sweep_runs, tmp_path):
    sweep, *_ = sweep_runs
    settings = []
    for key, value in SMALL.items():
        for name, item in (value.items() if isinstance(value, dict) else [(None, value)]):
            settings += ["--set", f"{key}.{name}={json.dumps(item)}" if name else f"{key}={json.dumps(item)}"]
    reference = tmp_path / "train"
    subprocess.run([*HRLSAC, "train", "--algo", "hrl-sac", "--seed", "3", "--steps", "800", "--out", str(reference),
                    "--quiet", *settings], check=True, timeout=300, cwd=ROOT)
    run = sweep.out / KILLED
    assert sorted(p.name for p in run.iterdir()) == sorted(p.name for p in reference.iterdir())
    assert json.loads((run / "config.json").read_text()) == json.loads((reference / "config.json").read_text())
    assert log_rows(run / "progress.csv") == log_rows(reference / "progress.csv")
    assert_same_state(torch.load(run / "checkpoint.pt", weights_only=False),
                      torch.load(reference / "checkpoint.pt", weights_only=False))


def test_hrlsac_train_trains_one_run_of_a_sweep_file_as_the_sweep_does(sweep_runs, tmp_path, monkeypatch):
    sweep, *_ = sweep_runs
    sweep_file = tmp_path / "tiny.yaml"
    sweep_file.write_text(json.dumps(SWEEP))  # JSON is YAML
    monkeypatch.chdir(tmp_path)  # the sweep file's relative 'out'
    result = run_cli("train", "--sweep", str(sweep_file), "--quiet")
    assert result.code == 2
    assert result.err.strip().endswith("give --run NAME; the sweep's runs: sac-default-seed3, hrl-sac-default-seed3")
    assert run_cli("train", "--sweep", str(sweep_file), "--run", KILLED, "--quiet").code == 0
    trained = tmp_path / "runs" / "tiny" / KILLED  # the folder the sweep file's 'out' gives the run
    run = sweep.out / KILLED
    assert json.loads((trained / "config.json").read_text()) == json.loads((run / "config.json").read_text())
    assert log_rows(trained / "progress.csv") == log_rows(run / "progress.csv")
    assert_same_state(torch.load(trained / "checkpoint.pt", weights_only=False),
                      torch.load(run / "checkpoint.pt", weights_only=False))
    # A changed sweep file is refused on --resume, naming the field.
    changed = tmp_path / "changed.yaml"
    changed.write_text(json.dumps({**SWEEP, "set": {**SMALL, "batch_size": 16}}))
    result = run_cli("train", "--sweep", str(changed), "--run", KILLED, "--out", str(trained), "--resume", "--quiet")
    assert result.code == 2 and "was trained with batch_size=32, the sweep now asks 16" in result.err


def test_a_sweep_refuses_run_folders_trained_with_another_config(sweep_runs):
    sweep, *_ = sweep_runs
    changed = sweep_from_dict({**SWEEP, "set": {**SMALL, "learning_rate": 0.001}}, out=sweep.out)
    with pytest.raises(ValueError, match="was trained with learning_rate=0.0003, the sweep now asks 0.001"):
        check_run_folders(changed)
    longer = sweep_from_dict({**SWEEP, "steps": 1600}, out=sweep.out)
    check_run_folders(longer)  # more steps: the runs are extended, not refused


# ---------------------------------------------------------------------------------------------- evaluation

@pytest.mark.parametrize("algo", ["sac", "hrl-sac"])
def test_parallel_evaluation_equals_serial_on_processes_and_ray(sweep_runs, algo):
    sweep, *_ = sweep_runs
    run = sweep.out / f"{algo}-default-seed3"
    serial = evaluate_checkpoint(run, "val", 11)
    assert serial["episodes"] == 11 and len(serial["per_episode"]["reward"]) == 11
    progress = []
    on_processes = evaluate_checkpoint(run, "val", 11, PoolConfig(workers=2), progress.append)
    assert progress in ([6, 11], [5, 11])  # the episodes flown, as each chunk (6 and 5 episodes) comes back
    assert on_processes == serial
    in_process = []  # one chunk, flown here: after every step, the episodes that have ended
    assert evaluate_checkpoint(run, "val", 11, on_progress=in_process.append) == serial
    assert in_process[-1] == 11 and in_process == sorted(in_process) and len(in_process) > 2
    # 4 chunks of 3, 3, 3 and 2 episodes (small batches are where torch's kernels would differ) on Ray.
    assert evaluate_checkpoint(run, "val", 11, PoolConfig(workers=4, ray_address="local")) == serial


def test_evaluate_command_with_workers_writes_the_serial_metrics(sweep_runs, tmp_path):
    sweep, *_ = sweep_runs
    run = sweep.out / f"{KILLED}"
    out = tmp_path / "eval.json"
    result = run_cli("evaluate", str(run), "--split", "val", "--episodes", "11", "--workers", "3", "--out", str(out))
    assert result.code == 0, result.err
    assert "evaluating 11 episodes on 3 local processes" in result.err
    written = json.loads(out.read_text())
    assert written.pop("scenarios") == "generator split val"  # the command labels what it flew
    assert written == evaluate_checkpoint(run, "val", 11)


# ---------------------------------------------------------------------------------------------- mission replay

def small_mission() -> Mission:
    scenario = Scenario(area=SearchArea(-100.0, 500.0, -300.0, 300.0), datum_north_m=250.0, datum_east_m=0.0,
                        datum_sigma_m=60.0, targets=(Target("person", 420.0, 150.0, primary=True),), name="small")
    flight = FlightSettings(altitude_m=20.0, max_speed_mps=8.0, max_steps=40, subgoal_interval=30)
    return Mission(scenario=scenario, flight=flight, name="small")


def replay_outputs(folder: Path) -> dict[str, bytes]:
    return {f"{seed.name}/{name}": (seed / name).read_bytes() for seed in sorted(folder.iterdir())
            for name in ("report.json", "flight.tlog")}


def test_replay_with_workers_gives_the_serial_reports_and_tlogs(ray_instance, tmp_path):
    save_mission(small_mission(), tmp_path / "small.yaml")
    # Without MAVLINK20 in the environment, as a user's shell runs it (the test suite's conftest sets it).
    env = {key: value for key, value in os.environ.items() if key != "MAVLINK20"}
    base = [*HRLSAC, "mission", "replay", str(tmp_path / "small.yaml"), "--policy", str(PRETRAINED),
            "--episodes", "3", "--seed", "4", "--no-video", "--quiet", "--accept-flight-mismatch"]
    # serial in this process; on worker processes started by a process whose environment lacks MAVLINK20
    assert run_cli(*base[len(HRLSAC):], "--out", str(tmp_path / "serial")).code == 0
    subprocess.run([*base, "--out", str(tmp_path / "processes"), "--workers", "2"], check=True, timeout=300, cwd=ROOT,
                   env=env)
    serial = replay_outputs(tmp_path / "serial")
    assert sorted(serial) == [f"seed-0000{s}/{f}" for s in (4, 5, 6) for f in ("flight.tlog", "report.json")]
    assert replay_outputs(tmp_path / "processes") == serial
    mission = load_mission(tmp_path / "small.yaml")
    episodes = [ReplayEpisode(mission, PilotChoice(policy=str(PRETRAINED)), seed, tmp_path / "ray" / f"seed-{seed:05d}",
                              video=False) for seed in (4, 5, 6)]
    reports = replay_episodes(episodes, PoolConfig(workers=2, ray_address="local"))
    assert replay_outputs(tmp_path / "ray") == serial
    assert [report["seed"] for report in reports] == [4, 5, 6]
