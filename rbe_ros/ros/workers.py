"""Plans (``~/plan``) and repairs (``~/plan_update``) in processes of their own.

A plan or a repair holds the GIL for seconds to minutes; in the node's process it halved the
rate of the as-built checks a cell waits on. Here they run in a pool of spawned processes
(forking a process with DDS threads is unsafe) at a lower priority (:data:`NICE`), so the
checks keep their latency while a plan runs; a plan's progress comes back through a queue
(the action's feedback) and a stop (cancel, a newer goal, shutdown) goes to it through an
event polled between candidate checks, as in the node's own process before. A process is
spawned at the first plan or repair, or when a plan to execute comes (its imports take
seconds: a node that never plans never pays them); like every spawned process, it imports
the main module again, so a script that makes a node needs the ``if __name__ ==
"__main__":`` guard.
"""
from __future__ import annotations

import os
import queue
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context

from rbe_msgs.msg import AssemblyState
from rclpy.serialization import deserialize_message

from ..analysis.lookahead import Checked
from ..analysis.options import CheckOptions
from ..analysis.planning import Plan, PlanProgress
from ..analysis.repair import Repair
from ..analysis.timeline import Timeline
from ..cell import Cell
from ..io.execution import Settings, repair
from ..io.plans import PlanLimits, plan_state
from ..scene import Scene
from .convert import scene_from_msg

#: Processes: a plan and a repair at the same time.
PROCESSES = 2
#: Niceness added to the worker processes: the node's checks come first.
NICE = 19
#: How often a running plan's progress and stop are looked at, s.
POLL_S = 0.05

_progress = None        # in a worker: the queue of plan progress
_stop = None            # in a worker: the event that stops the plan running


def _init(progress, stop) -> None:
    global _progress, _stop
    _progress, _stop = progress, stop
    try:
        os.nice(NICE)
    except OSError:     # not permitted: the same priority, still another process
        pass


def _plan(job: int, assembly: bytes, limits: PlanLimits, options: CheckOptions) -> Plan:
    """In a worker: plan the CDR AssemblyState ``assembly`` as the node's dispatch does,
    its progress tagged with ``job``."""
    def read() -> Scene:
        return scene_from_msg(deserialize_message(assembly, AssemblyState),
                              limits=options.limits)

    return plan_state(read, limits, options, progress=lambda p: _progress.put((job, p)),
                      should_stop=_stop.is_set)


class Workers:
    """The node's pool of worker processes."""

    def __init__(self) -> None:
        self._context = get_context("spawn")
        self._progress = self._context.Queue()
        self._stop = self._context.Event()
        self._jobs = 0
        self._pool = self._start()

    def _start(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(PROCESSES, mp_context=self._context, initializer=_init,
                                   initargs=(self._progress, self._stop))

    def _submit(self, fn, *args):
        try:
            return self._pool.submit(fn, *args)
        except BrokenProcessPool:           # a worker died (killed): a new pool
            self._pool = self._start()
            return self._pool.submit(fn, *args)

    def plan(self, assembly: bytes, limits: PlanLimits, options: CheckOptions, *,
             progress: Callable[[PlanProgress], None], should_stop: Callable[[], bool]
             ) -> Plan:
        """Plan in a worker (one plan at a time: the caller's lock); ``progress`` gets
        each step placed, ``should_stop`` is polled and stops the plan (the best partial
        plan is returned, as by :func:`plan_state`)."""
        self._stop.clear()
        self._jobs += 1
        future = self._submit(_plan, self._jobs, assembly, limits, options)
        while True:
            try:
                job, placed = self._progress.get(timeout=POLL_S)
                if job == self._jobs:       # not a late one of a plan before
                    progress(placed)
                continue
            except queue.Empty:
                pass
            if future.done():
                break
            if should_stop():
                self._stop.set()
        return future.result()

    def warm(self) -> None:
        """Spawn a process now (a plan to execute came: its first repair need not wait for
        the imports)."""
        self._submit(time.sleep, 0.0)

    def repair(self, plan: Scene, built: Scene, options: CheckOptions, settings: Settings,
               cell: Cell | None = None, checked: Checked | None = None
               ) -> tuple[Repair, Timeline | None]:
        """:func:`rbe_ros.io.execution.repair` in a worker."""
        return self._submit(repair, plan, built, options, settings, cell, checked).result()

    def close(self) -> None:
        """Stop the processes now (a plan or repair running is not waited for) and the
        pool's thread with them (left running, it fails at the interpreter's exit)."""
        self._stop.set()
        for process in list((getattr(self._pool, "_processes", None) or {}).values()):
            process.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)


__all__ = ["NICE", "PROCESSES", "Workers"]
