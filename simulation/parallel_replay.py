"""Many mission replays (one per seed) spread over worker processes or a Ray cluster.

A replay is a pure function of (mission, pilot, seed, options): lockstep simulated time, seeded
sensor noise and detections. So each episode is one task, run wherever there is a free CPU, and its tlog and
report are byte-identical to the serial run's. Workers load the pilot (an artifact from its path, once per process) and
write their episode's folder themselves, so on a multi-node cluster both the artifact and the output folder
must be on a filesystem every node sees (docs/scaling.md).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from autonomy.pilots import PilotChoice
from autonomy.search_pilot import FlownPolicy
from missions.mission import Mission
from simulation.worker_pool import PoolConfig, run_tasks

_loaded: dict[str, FlownPolicy] = {}  # artifact path -> policy, per worker process


@dataclass(frozen=True)
class ReplayEpisode:
    """One replay for one worker."""

    mission: Mission
    """The mission flown."""
    pilot: PilotChoice
    """What flies: a policy artifact (loaded by the worker from its path, reported as given) or a scripted
    searcher."""
    seed: int
    """Seed of the vehicle's sensor noise and of the simulated camera's detections."""
    out: Path | None
    """Folder for flight.tlog, report.json, trajectory.png (and replay.mp4); None = write nothing."""
    video: bool = True
    """Also write replay.mp4."""
    narrate: bool = False
    """Print the mission's progress lines (useful for a single episode in this process)."""
    options: dict[str, Any] = field(default_factory=dict)
    """Further keyword arguments of :func:`simulation.mission_replay.replay_mission` (signing key, link faults)."""


def replay_episode(episode: ReplayEpisode) -> dict:
    """Fly one episode; its report (runs in a worker, or in this process)."""
    from simulation.mission_replay import replay_mission

    speak_mavlink2()
    if episode.pilot.policy is None:
        policy = episode.pilot.load()  # a scripted searcher keeps the state of one flight: a fresh one each
    else:
        policy = _loaded.get(episode.pilot.policy)
        if policy is None:
            policy = _loaded[episode.pilot.policy] = episode.pilot.load()
    say = print if episode.narrate else _silent
    return replay_mission(episode.mission, policy, seed=episode.seed, out=episode.out, video=episode.video, say=say,
                          **episode.options)


def replay_episodes(episodes: list[ReplayEpisode], pool: PoolConfig,
                    on_done: Callable[[int, dict], None] | None = None) -> list[dict]:
    """The reports of ``episodes``, in order, flown on ``pool``; ``on_done(index, report)`` as each ends."""
    return run_tasks(replay_episode, episodes, pool, on_done)


def speak_mavlink2() -> None:
    """Make pymavlink speak MAVLink 2 from the first byte in this process. Without ``MAVLINK20`` in the
    environment it sends MAVLink 1 until it hears MAVLink 2, then switches for the whole process: the first
    replay in a process would start its tlog with MAVLink 1 heartbeats and later ones with MAVLink 2, so an
    episode's tlog would depend on which episodes its worker flew before it."""
    if "MAVLINK20" not in os.environ:
        os.environ["MAVLINK20"] = "1"
        from pymavlink import mavutil

        mavutil.set_dialect(mavutil.current_dialect)


def _silent(text: str) -> None:
    """A ``say`` that prints nothing (a module-level function, so that it pickles)."""
