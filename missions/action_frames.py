"""How a policy's two movement components become a velocity: the action frames of SarSearch-v1.

The environment (``policies.env.core``), the scripted searchers and the flight runtime's pilot
(``autonomy.search_pilot``) all read a movement through :func:`movement_velocity`, so that a policy flies in the
air exactly as it was trained.
"""
from __future__ import annotations

from enum import StrEnum

import numpy as np


class ActionFrame(StrEnum):
    """How a policy's two movement components are read (``SarSearchConfig.action_frame``, in the artifact's manifest
    as its value)."""

    NORTH_EAST = "north_east"
    """Velocity north and east, each as a share of the top speed (the paper's; SarSearch-v0's only)."""
    TARGET = "target"
    """Towards the observation's target point and to the right of that line, as shares of the top speed, so that
    flying straight at the target is the constant action (1, 0)."""
    ARRIVE = "arrive"
    """As TARGET, with the speed also capped by what covers the rest of the way in one step
    (:func:`arrival_speed_fraction`), so that (1, 0) flies straight at the target *and stops on it*: a close look or
    a return home is the same constant action as the flight there (the scripted searchers fly the same way)."""


ACTION_FRAMES: tuple[str, ...] = tuple(frame.value for frame in ActionFrame)
"""The action frames' names, as configs and manifests spell them."""


def check_action_frame(owner: str, frame: str, task: str) -> None:
    """Raise one ValueError naming ``owner``'s field unless ``frame`` is an action frame the ``task`` supports."""
    if frame not in ACTION_FRAMES or (frame != ActionFrame.NORTH_EAST and task != "SarSearch-v1"):
        raise ValueError(f"{owner}.action_frame must be 'north_east', or on SarSearch-v1 'target' or 'arrive', got "
                         f"{frame!r} on {task}")


ARRIVAL_STEPS = 2.0
"""The arrival speed covers the rest of the way in this many steps: a proportional gain of 1 / (2 s) at 1 s steps,
about critically damped for the multirotor's velocity response (time constant 0.5 s, ``sitl_bridge.multirotor``),
so that the drone stops on the point instead of overshooting it (with one step it passes a point it reaches at
full speed by 7.5 m)."""


def arrival_speed_fraction(distance_m: np.ndarray, max_speed_mps: float, step_period_s: float,
                           steps: float = ARRIVAL_STEPS) -> np.ndarray:
    """Share of the top speed that covers ``distance_m`` in ``steps`` steps: 1 far away, falling to 0 on the point,
    so that a drone flying at it slows down on the way in. The scripted searchers use one step (they were tuned
    with it; they turn at a waypoint before they would overshoot it)."""
    return np.minimum(1.0, distance_m / (steps * max_speed_mps * step_period_s))


def movement_velocity(movement: np.ndarray, position: np.ndarray, target: np.ndarray, frame: ActionFrame | str,
                      max_speed_mps: float, step_period_s: float) -> np.ndarray:
    """(N, 2) velocity north / east (m/s) commanded by the policy's movement components (N, 2), read in ``frame``
    (:class:`ActionFrame`) relative to the drone's ``position`` and the observation's ``target`` (both (N, 2))."""
    if frame == ActionFrame.NORTH_EAST:
        return movement * max_speed_mps
    velocity = target_frame_to_north_east(movement, position, target) * max_speed_mps
    if frame == ActionFrame.ARRIVE:
        distance = np.hypot(*(target - position).T)
        velocity *= arrival_speed_fraction(distance, max_speed_mps, step_period_s)[:, None]
    return velocity


def target_frame_to_north_east(movement: np.ndarray, position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N, 2) movement commands given towards the target point and to the right of the line to it (SarSearch-v1's
    ``ActionFrame.TARGET``), as north and east components. At the target itself (closer than 1 cm) towards is
    north."""
    offset = target - position
    distance = np.hypot(*offset.T)
    towards = np.where((distance > 0.01)[:, None], offset / np.maximum(distance, 0.01)[:, None], (1.0, 0.0))
    right = np.stack([-towards[:, 1], towards[:, 0]], axis=1)  # facing north, the right hand points east
    return movement[:, 0:1] * towards + movement[:, 1:2] * right
