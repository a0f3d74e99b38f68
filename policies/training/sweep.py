"""A sweep of training runs on Ray: each grid point is one Ray task that trains one run folder.

A run's task is idempotent: it trains its folder to ``total_steps``, starting fresh when there is no
checkpoint, resuming exactly from the checkpoint when there is one (``Trainer(resume=True)``, the same as
``hrlsac train --resume``), and returning at once when the checkpoint is already at ``total_steps``. So

* re-running a sweep skips finished runs and resumes interrupted ones from their last checkpoint;
* a worker that dies (killed, out of memory, a lost node) is restarted by Ray up to ``retries`` times, and the
  restart resumes the run; past that the run is reported failed and the next ``hrlsac sweep`` resumes it.

The run folders are exactly what ``hrlsac train --out FOLDER`` writes (config.json, progress.csv,
checkpoint.pt, tensorboard/), so every other command (evaluate, compare, export) works on them unchanged. The
sweep folder also gets ``sweep.json``: every run's state, steps and training success after the last sweep.
"""
from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from autonomy.recorder import write_json_atomic
from policies.checkpoint import CHECKPOINT
from policies.config import TrainConfig
from policies.reports.sweep_table import DONE, FAILED, PENDING, RUNNING, SKIPPED, ProgressTable, RunStatus
from policies.training.sweep_config import RunSpec, SweepConfig
from simulation.worker_pool import connect_ray, limit_threads, ray_cpus

SWEEP_REPORT = "sweep.json"


@dataclass(frozen=True)
class RunTask:
    """What one Ray task gets: the run and, in tests only, a simulated crash."""

    spec: RunSpec
    """The run to train."""
    kill_at_step: int | None = None
    """Fault injection (tests): train to this step (a multiple of checkpoint_every, so the checkpoint there is
    the periodic one), then SIGKILL the worker process, as a crash would. Only when starting below it."""


def train_run(task: RunTask) -> dict:
    """Train one run folder to its ``total_steps`` (fresh, resumed, or nothing to do). Runs in a Ray worker."""
    from policies.evaluation.parallel import quick_evaluation
    from policies.training.trainer import Trainer

    limit_threads()
    spec, folder = task.spec, task.spec.folder
    if (folder / CHECKPOINT).exists():
        trainer = Trainer(spec.config, folder, resume=True, evaluate=quick_evaluation)
        if trainer.step >= spec.config.total_steps:
            return _result(SKIPPED, trainer, "finished before this sweep")
        note = f"resumed at step {trainer.step:,}"
    else:
        _clear_partial_run(folder)
        trainer = Trainer(spec.config, folder, evaluate=quick_evaluation)
        note = ""
    if task.kill_at_step is not None and trainer.step < task.kill_at_step:
        trainer.run(progress=False, stop_at=task.kill_at_step)
        os.kill(os.getpid(), signal.SIGKILL)
    trainer.run(progress=False)
    return _result(DONE, trainer, note)


def _result(state: str, trainer, message: str) -> dict:
    recent = [episode[0] for episode in trainer.recent]
    return {"state": state, "steps": trainer.step, "message": message,
            "success_rate": sum(recent) / len(recent) if recent else math.nan}


def _clear_partial_run(folder: Path) -> None:
    """A run killed before its first checkpoint left logs of steps that will be trained again: remove them, so
    the fresh run's progress.csv and TensorBoard log are what an uninterrupted run writes."""
    (folder / "progress.csv").unlink(missing_ok=True)
    shutil.rmtree(folder / "tensorboard", ignore_errors=True)


def check_run_folders(sweep: SweepConfig) -> None:
    """Refuse to resume a run folder trained with another config (the sweep file changed): ValueError naming the
    run and the first field that differs. Only ``total_steps`` may change (the run is extended or left alone)."""
    for spec in sweep.runs:
        path = spec.folder / "config.json"
        if not path.exists():
            continue
        difference = config_difference(json.loads(path.read_text()), spec.config)
        if difference:
            raise ValueError(f"run folder {spec.folder} was trained with {difference}; restore the sweep file or "
                             "choose another out")


def config_difference(stored: dict, wanted: TrainConfig) -> str | None:
    """The first field other than ``total_steps`` in which a run folder's config.json (``stored``) differs from
    ``wanted``, as "FIELD=STORED, the sweep now asks WANTED"; None when they agree."""
    wanted_dict = json.loads(json.dumps(wanted.to_dict()))
    for key in sorted(set(stored) | set(wanted_dict)):
        if key != "total_steps" and stored.get(key) != wanted_dict.get(key):
            return f"{key}={stored.get(key)!r}, the sweep now asks {wanted_dict.get(key)!r}"
    return None


def latest_progress(folder: Path) -> tuple[int, float] | None:
    """(step, success rate) of the last row of a run's progress.csv, or None before its first row."""
    try:
        with open(folder / "progress.csv", newline="") as handle:
            rows = list(csv.DictReader(handle))
    except FileNotFoundError:
        return None
    if not rows:
        return None
    try:
        return int(rows[-1]["step"]), float(rows[-1]["success_rate"])
    except (KeyError, ValueError):  # a row being written right now
        return None


def run_sweep(sweep: SweepConfig, ray_address: str = "local", max_parallel: int | None = None,
              table: ProgressTable | None = None, refresh_s: float = 1.0,
              kill_at: dict[str, int] | None = None,
              on_refresh: Callable[[list[RunStatus]], None] | None = None) -> list[RunStatus]:
    """Train every run of ``sweep`` on Ray (started here for ``"local"``, joined otherwise), at most
    ``max_parallel`` at once (default: the sweep file's, else one per cluster CPU); the table is refreshed every
    ``refresh_s`` seconds. Returns the final status of every run and writes ``sweep.json``. Ctrl-C cancels the
    running tasks (their runs keep their last checkpoints) and re-raises. ``kill_at``: fault injection for tests
    (run name -> step, see :class:`RunTask`)."""
    check_run_folders(sweep)
    ray = connect_ray(ray_address)
    parallel = max_parallel or sweep.max_parallel or ray_cpus(ray)
    remote = ray.remote(num_cpus=1, max_retries=sweep.retries)(train_run)
    table = table or ProgressTable()
    statuses = [RunStatus(spec.name, spec.folder, spec.config.total_steps) for spec in sweep.runs]
    waiting = list(range(len(sweep.runs)))
    running: dict = {}  # ObjectRef -> run index
    try:
        while waiting or running:
            while waiting and len(running) < parallel:
                index = waiting.pop(0)
                task = RunTask(sweep.runs[index], (kill_at or {}).get(sweep.runs[index].name))
                running[remote.remote(task)] = index
                statuses[index].state = RUNNING
            finished, _ = ray.wait(list(running), num_returns=1, timeout=refresh_s)
            for ref in finished:
                _finish(statuses[running.pop(ref)], ray, ref)
            for index in running.values():
                _refresh(statuses[index])
            table.update(statuses)
            if on_refresh is not None:
                on_refresh(statuses)
    except BaseException:
        for ref in running:
            ray.cancel(ref, force=True)
        for index in running.values():
            statuses[index].state, statuses[index].message = FAILED, "interrupted"
        raise
    finally:
        _write_report(sweep, statuses)
    table.finish(statuses)
    return statuses


def _finish(status: RunStatus, ray, ref) -> None:
    try:
        result = ray.get(ref)
    except Exception as exc:  # RayTaskError (the run raised), WorkerCrashedError (its process died), ...
        status.state, status.message = FAILED, _one_line(exc)
        _refresh(status)
        return
    status.state, status.steps, status.message = result["state"], result["steps"], result["message"]
    status.success_rate = result["success_rate"]


def _refresh(status: RunStatus) -> None:
    progress = latest_progress(status.folder)
    if progress is not None:
        status.steps, status.success_rate = progress


def _one_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    reason = lines[-1] if lines else type(exc).__name__
    return f"{type(exc).__name__}: {reason}"[:200]


def _write_report(sweep: SweepConfig, statuses: list[RunStatus]) -> None:
    sweep.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(sweep.out / SWEEP_REPORT, {
        "sweep": sweep.name, "grid_fields": list(sweep.grid_fields),
        "runs": [{**status.as_dict(), "algo": spec.config.algo, "preset": spec.config.preset,
                  "seed": spec.config.seed} for status, spec in zip(statuses, sweep.runs)]})


def pending_runs(statuses: list[RunStatus]) -> list[str]:
    """Names of runs that did not finish (failed or never started)."""
    return [status.name for status in statuses if status.state in (FAILED, PENDING, RUNNING)]
