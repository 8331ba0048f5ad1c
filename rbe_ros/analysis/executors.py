"""Where the batches of a Monte Carlo study, the planner's full checks of the steps ahead,
and a repair's checks of the remaining steps run: a local process pool or a Ray cluster.

Both map :func:`rbe_ros.analysis.robust.run_batch` over the batches and yield the results in
batch order; since every sample is seeded by its index, the numbers are the executor's
business only in speed. For the planner (:class:`CheckPool`, :func:`ray_checks`) each task is
the full check of one step, the same wherever it runs. Workers import the ROS-free core
only (no rclpy) and run one solver thread each: the processes are the parallelism.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from .assembly import Assembly
from .options import CheckOptions
from .pipeline import Placed, _completed, slim
from .robust import RobustJob, SampleResult, run_batch
from .steps import gripped
from .verdict import check

#: Thread pools of numeric libraries capped at one thread per worker process.
_ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                "RAYON_NUM_THREADS")}


@contextmanager
def _one_thread_env():
    """Children spawned inside inherit one-thread settings (the parent's are restored)."""
    saved = {k: os.environ.get(k) for k in _ONE_THREAD}
    os.environ.update(_ONE_THREAD)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class ProcessPool:
    """An executor of ``workers`` spawned processes (spawn: no state forked from the caller,
    which may be a ROS node with threads), kept for later studies until :meth:`close`: a
    spawned worker spends a second or more importing the core before its first sample."""

    def __init__(self, workers: int):
        if workers < 1:
            raise ValueError(f"workers must be at least 1, not {workers}")
        self.pool = ProcessPoolExecutor(max_workers=workers,
                                        mp_context=multiprocessing.get_context("spawn"))

    def __call__(self, job: RobustJob, parts: list[range]) -> Iterator[list[SampleResult]]:
        with _one_thread_env():                 # workers are spawned on submission
            futures = [self.pool.submit(run_batch, job, part) for part in parts]
        for f in futures:
            yield f.result()

    def close(self) -> None:
        self.pool.shutdown(cancel_futures=True)

    def __enter__(self) -> ProcessPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


#: The assembly and options of a planner's or repair's worker process (set once, by
#: _plan_worker).
_PLAN: dict = {}


def _plan_worker(assembly: Assembly, options: CheckOptions) -> None:
    # Ctrl-C reaches the whole process group: the planner stops and returns its partial
    # plan, which needs its workers' pending results, not their KeyboardInterrupt
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _PLAN.update(assembly=assembly, options=options)


def _planner_processes(assembly: Assembly, options: CheckOptions,
                       workers: int) -> ProcessPoolExecutor:
    """``workers`` spawned processes, each given the assembly and options once."""
    if workers < 1:
        raise ValueError(f"workers must be at least 1, not {workers}")
    return ProcessPoolExecutor(max_workers=workers, initializer=_plan_worker,
                               initargs=(assembly, options),
                               mp_context=multiprocessing.get_context("spawn"))


def _check_step(present: tuple[str, ...], held: tuple[str, ...], assembly=None, options=None):
    """The full check of one step of the planner's assembly (a worker's, or the given), a
    robot's grip on each held block: the check the planner makes of a trial itself when
    no smaller model settles it."""
    assembly = _PLAN["assembly"] if assembly is None else assembly
    options = _PLAN["options"] if options is None else options
    return check(gripped(assembly, present, held), options)


class CheckPool:
    """The planner's look-ahead (:class:`rbe_ros.analysis.planning.LookAhead`) on
    ``workers`` spawned processes, each given the assembly once."""

    def __init__(self, assembly: Assembly, options: CheckOptions, workers: int):
        self.workers, self.pool = workers, _planner_processes(assembly, options, workers)

    def submit(self, present, held):
        with _one_thread_env():                 # workers are spawned on submission
            return self.pool.submit(_check_step, tuple(present), tuple(sorted(held)))

    def close(self) -> None:
        self.pool.shutdown(cancel_futures=True)


def _whole_step(present, held, grips, block, approach, tolerance: bool):
    """The whole check of one step of the worker's assembly, completed as
    :class:`rbe_ros.analysis.lookahead.StepRunner` completes it (slim)."""
    assembly, options = _PLAN["assembly"], _PLAN["options"]
    state = assembly.subset(present, held, grips)
    return slim(_completed(check(state, options), state, held, options,
                           Placed(assembly, present, block, approach), tolerance=tolerance))


class StepPool:
    """Whole-step checks of a look-ahead or repair (:class:`rbe_ros.analysis.lookahead.
    StepRunner`) on ``workers`` spawned processes, each given the assembly (every block at
    its as-built or design pose) once: ``submit(...)`` takes :func:`_whole_step`'s
    arguments and returns a future of the step's slim report."""

    def __init__(self, assembly: Assembly, options: CheckOptions, workers: int):
        self.workers, self.pool = workers, _planner_processes(assembly, options, workers)

    def submit(self, *args):
        with _one_thread_env():                 # workers are spawned on submission
            return self.pool.submit(_whole_step, *args)

    def close(self) -> None:
        # a check under way finishes in its worker, which then exits: nothing waits for it
        self.pool.shutdown(wait=False, cancel_futures=True)


class _RayFuture:
    def __init__(self, ray, ref):
        self.ray, self.ref = ray, ref

    def result(self):
        return self.ray.get(self.ref)

    def cancel(self) -> None:
        self.ray.cancel(self.ref)


def ray_checks(address: str | None, workers: int = 2, **init):
    """A look-ahead factory (``plan_sequence(look_ahead=...)``) sending each step's check
    as a Ray task (one CPU each) to the cluster at ``address`` (as :func:`ray_cluster`),
    ``workers`` steps ahead; the assembly is put in the object store once."""
    ray = _ray()

    class RayChecks:
        def __init__(self, assembly: Assembly, options: CheckOptions):
            _ray_init(ray, address, init)
            self.workers = workers
            self.refs = ray.put(assembly), ray.put(options)
            self.remote = ray.remote(num_cpus=1)(_check_step)

        def submit(self, present, held):
            return _RayFuture(ray, self.remote.remote(tuple(present), tuple(sorted(held)),
                                                      *self.refs))

        def close(self) -> None:
            pass                              # the cluster outlives the plan
    return RayChecks


def _ray():
    try:
        import ray                # optional dependency, only needed on this path
    except ImportError as exc:
        raise RuntimeError("--ray needs Ray: pip install -r requirements/ray.txt") from exc
    return ray


def _ray_init(ray, address, init) -> None:
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=False,
                 runtime_env={"env_vars": _ONE_THREAD}, **init)


def ray_cluster(address: str | None, **init):
    """An executor sending each batch as a Ray task (one CPU each) to the cluster at
    ``address`` ("auto": the one this machine belongs to; None: a new local instance, with
    ``init`` passed to ``ray.init``, e.g. num_cpus=2). Ray is optional:
    ``pip install -r requirements/ray.txt``."""
    ray = _ray()

    def run(job: RobustJob, parts: list[range]) -> Iterator[list[SampleResult]]:
        _ray_init(ray, address, init)
        remote = ray.remote(num_cpus=1)(run_batch)
        job_ref = ray.put(job)
        refs = [remote.remote(job_ref, part) for part in parts]
        for ref in refs:
            yield ray.get(ref)
    return run
