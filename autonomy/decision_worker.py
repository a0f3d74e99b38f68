"""Policy decisions off the control loop: a thread in real time, a simulated latency in lockstep.

The runner's loop must keep streaming setpoints whatever the policy does; :class:`DecisionWorker` runs
``SearchPilot.decide`` beside it. In real time the decision runs in a thread (a slow policy delays decisions, never
setpoints); in lockstep it runs synchronously and its answer is released after ``compute_time_s`` of simulated time
(0 unless a test makes a policy slow), so that replays stay deterministic.
"""
from __future__ import annotations

import threading

import numpy as np

from autonomy.search_pilot import Decision, SearchPilot


class DecisionWorker:
    """Runs ``pilot.decide`` off the control loop; ``threaded`` in real time, simulated latency in lockstep."""

    def __init__(self, pilot: SearchPilot, threaded: bool, simulated_compute_s: float = 0.0):
        self.pilot, self.threaded = pilot, threaded
        self.compute_time_s = simulated_compute_s
        self._pending: tuple[float, Decision] | None = None
        self._thread: threading.Thread | None = None
        self._result: Decision | None = None

    @property
    def busy(self) -> bool:
        return self._pending is not None or (self._thread is not None and self._thread.is_alive())

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        if self.threaded:
            def work() -> None:
                self._result = self.pilot.decide(position_ne)
            self._thread = threading.Thread(target=work, name="policy", daemon=True)
            self._thread.start()
        else:
            self._pending = (now_s + self.compute_time_s, self.pilot.decide(position_ne))

    def poll(self, now_s: float) -> Decision | None:
        """The finished decision, once (None while computing or idle)."""
        if self.threaded:
            if self._thread is not None and not self._thread.is_alive():
                self._thread, result, self._result = None, self._result, None
                return result
            return None
        if self._pending is not None and now_s + 1e-9 >= self._pending[0]:
            decision, self._pending = self._pending[1], None
            return decision
        return None
