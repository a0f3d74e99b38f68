"""Run independent tasks on local worker processes or on a Ray cluster, results in task order.

The one place that knows how work is spread over CPUs. Callers give a module-level function and a list of
picklable tasks; :func:`run_tasks` returns ``[fn(task) for task in tasks]``, run

* in this process when ``workers == 1`` and no Ray address is given (the serial path, no pool at all);
* on ``workers`` local processes (``concurrent.futures`` with the *spawn* context: a fresh interpreter, so no
  torch or Ray state is inherited from the parent by a fork) when no Ray address is given;
* as Ray tasks (one CPU each) when an address is given: ``"local"`` starts a Ray instance on this machine,
  ``"auto"`` joins the cluster this machine is part of (``ray start``), ``"ray://HOST:PORT"`` connects as a
  Ray Client. If Ray is already initialised in this process (a test fixture, a sweep), it is reused.

Every worker computes with one torch thread: the tasks are already spread over the cores, more threads per
worker only contend (and a different thread count could change floating-point reduction order).

It imports nothing of the project (``autonomy`` for the mission replay, ``policies`` for evaluation and sweeps
both use it) and imports Ray only when an address is given, so the runtime works without Ray installed.
"""
from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
from dataclasses import dataclass
from typing import Any, Callable, Sequence

RAY_EXTRA = "pip install 'hrlsac[ray]'"
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


class WorkerPoolError(RuntimeError):
    """A pool that cannot be used (Ray missing or unreachable); the message is one line for the user."""


@dataclass(frozen=True)
class PoolConfig:
    """Where the tasks of one command run."""

    workers: int = 1
    """How many tasks run at once: local processes, or the cap on concurrent Ray tasks. 1 without a Ray address
    runs everything in this process."""
    ray_address: str | None = None
    """None: local processes. "local": a Ray instance started on this machine; "auto": the Ray cluster this
    machine belongs to (``ray start --address``); "ray://HOST:PORT": a remote cluster through Ray Client."""

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or not 1 <= self.workers <= 4096:
            raise ValueError(f"--workers must be an integer in [1, 4096], got {self.workers!r}")
        if self.ray_address is not None:
            address = self.ray_address
            if not (address in ("local", "auto") or address.startswith("ray://") or ":" in address):
                raise ValueError(f"--ray must be 'local', 'auto', 'ray://HOST:PORT' or a GCS 'HOST:PORT', "
                                 f"got {address!r}")

    @property
    def uses_ray(self) -> bool:
        return self.ray_address is not None

    def describe(self) -> str:
        """Where the work runs, for progress lines ("2 local processes", "Ray at ray://head:10001")."""
        if self.uses_ray:
            return f"Ray ({self.ray_address}), up to {self.workers} at once"
        return "this process" if self.workers == 1 else f"{self.workers} local processes"


def contiguous_chunks(count: int, parts: int) -> list[range]:
    """Split ``range(count)`` into at most ``parts`` contiguous, non-empty ranges whose sizes differ by at
    most one, in order (so that concatenating per-chunk results gives the serial order)."""
    parts = max(1, min(parts, count))
    size, extra = divmod(count, parts)
    chunks, start = [], 0
    for index in range(parts):
        stop = start + size + (1 if index < extra else 0)
        chunks.append(range(start, stop))
        start = stop
    return [chunk for chunk in chunks if len(chunk)]


def run_tasks(fn: Callable[[Any], Any], tasks: Sequence[Any], pool: PoolConfig,
              on_done: Callable[[int, Any], None] | None = None) -> list[Any]:
    """``[fn(task) for task in tasks]`` computed on ``pool``; ``on_done(index, result)`` is called in this
    process as each task finishes (in completion order), for progress output. ``fn`` must be importable by
    name (a module-level function) so that workers can load it. A task that raises re-raises here."""
    tasks = list(tasks)
    if pool.uses_ray:
        return _run_on_ray(fn, tasks, pool, on_done)
    if pool.workers == 1 or len(tasks) <= 1:
        results = []
        for index, task in enumerate(tasks):
            results.append(_single_threaded(fn, task))
            if on_done is not None:
                on_done(index, results[-1])
        return results
    return _run_on_processes(fn, tasks, pool.workers, on_done)


def limit_threads() -> None:
    """One compute thread in this process (torch, and the BLAS libraries numpy uses when they start later)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        import torch
    except ImportError:  # a worker that never computes with torch
        return
    torch.set_num_threads(1)


def _single_threaded(fn: Callable[[Any], Any], task: Any) -> Any:
    """``fn(task)`` with one torch thread, restoring the caller's thread count afterwards."""
    try:
        import torch
    except ImportError:
        return fn(task)
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return fn(task)
    finally:
        torch.set_num_threads(previous)


def _run_on_processes(fn, tasks: list, workers: int, on_done) -> list:
    results: list[Any] = [None] * len(tasks)
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=context,
                                                initializer=limit_threads) as executor:
        futures = {executor.submit(fn, task): index for index, task in enumerate(tasks)}
        try:
            for future in concurrent.futures.as_completed(futures):
                index = futures[future]
                results[index] = future.result()
                if on_done is not None:
                    on_done(index, results[index])
        except BaseException:
            for future in futures:  # Ctrl-C or a failed task: do not start the rest
                future.cancel()
            raise
    return results


RAY_WORKER_NICENESS = "0"
"""Niceness of the workers of a Ray instance started here (``RAY_worker_niceness``, unless the environment sets it).
Ray's own default, 15, suits nodes that do nothing else; on a shared workstation its workers then get a few percent
of a core beside any busy process, and a sweep or a parallel evaluation crawls while the machine looks idle."""


def start_local_ray(**options):
    """Start a Ray instance in this process with its workers at ``RAY_WORKER_NICENESS`` and no usage stats
    (offline machines); ``options`` go to ``ray.init`` (``num_cpus``...). Returns the ``ray`` module."""
    import ray

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage-stats prompt or upload
    os.environ.setdefault("RAY_worker_niceness", RAY_WORKER_NICENESS)
    ray.init(include_dashboard=False, log_to_driver=False, **options)
    return ray


def connect_ray(address: str):
    """The ``ray`` module, initialised: reused if this process already joined a Ray instance, else started
    locally (``"local"``) or connected to ``address``. Raises :class:`WorkerPoolError` with a one-line reason."""
    try:
        import ray
    except ImportError:
        raise WorkerPoolError(f"--ray needs Ray, which is not installed: {RAY_EXTRA}") from None
    if ray.is_initialized():
        return ray
    try:
        if address == "local":
            start_local_ray()
        else:
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage-stats prompt or upload
            ray.init(address=address, log_to_driver=False)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise WorkerPoolError(f"cannot join the Ray cluster at {address!r}: {first_line}") from None
    return ray


def _on_ray_worker(fn: Callable[[Any], Any], task: Any) -> Any:
    limit_threads()
    return fn(task)


def _run_on_ray(fn, tasks: list, pool: PoolConfig, on_done) -> list:
    ray = connect_ray(pool.ray_address)
    remote = ray.remote(num_cpus=1, max_retries=1)(_on_ray_worker)
    fn_ref = ray.put(fn)
    results: list[Any] = [None] * len(tasks)
    waiting = list(enumerate(tasks))
    running: dict[Any, int] = {}
    try:
        while waiting or running:
            while waiting and len(running) < pool.workers:  # at most ``workers`` tasks queued on the cluster
                index, task = waiting.pop(0)
                running[remote.remote(fn_ref, task)] = index
            finished, _ = ray.wait(list(running), num_returns=1)
            for ref in finished:
                index = running.pop(ref)
                results[index] = ray.get(ref)
                if on_done is not None:
                    on_done(index, results[index])
    except BaseException:
        for ref in running:
            ray.cancel(ref, force=True)
        raise
    return results


def add_pool_arguments(parser) -> None:
    """``--workers N`` and ``--ray ADDRESS`` on an argparse parser (evaluate, mission replay)."""
    parser.add_argument("--workers", type=int, default=None,
                        help="split the episodes across N local processes, or N concurrent Ray tasks with --ray "
                             "(default: 1, with --ray the cluster's CPUs)")
    parser.add_argument("--ray", metavar="ADDRESS", default=None,
                        help="run the workers on Ray: 'local' (start Ray here), 'auto' (the cluster this machine "
                             "joined with 'ray start') or 'ray://HOST:PORT'; needs " + RAY_EXTRA)


def pool_from_arguments(args) -> PoolConfig:
    """The :class:`PoolConfig` of parsed ``--workers`` / ``--ray`` (ValueError naming the option if invalid;
    with --ray and no --workers, joins Ray to count its CPUs, WorkerPoolError if it cannot)."""
    workers = args.workers
    if workers is None:
        PoolConfig(ray_address=args.ray)  # validate the address before connecting to it
        workers = ray_cpus(connect_ray(args.ray)) if args.ray else 1
    return PoolConfig(workers=workers, ray_address=args.ray)


def ray_cpus(ray) -> int:
    """CPUs of the Ray cluster this process joined (at least 1)."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))
