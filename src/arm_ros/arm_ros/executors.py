"""A MultiThreadedExecutor that waits instead of spinning while its work is queued.

rclpy's (Jazzy) MultiThreadedExecutor hands each ready callback to a thread pool as a Task, and on its
next turn yields every Task that has not started executing yet, again. While the pool's threads are
slow to pick a Task up (all busy, or waiting for the GIL behind a long callback such as an MPPI plan),
the executor's thread resubmits the same Tasks in a tight loop: measured in plan_node with /clock and
/joint_states at 41 Hz, that loop took 8-10 s of CPU in a 13 s plan and tripled the plan's wall time.

Here a Task yielded again while its earlier submission is still queued or running is not resubmitted:
the executor's thread sleeps (GIL released) until some submitted callback finishes, or 5 ms at most.
A Task whose earlier run has returned without finishing (a coroutine awaiting a future) is resubmitted
as before.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future as PoolFuture

from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    TimeoutException,
)

REQUEUED_WAIT_S = 0.005


class QueueAwareMultiThreadedExecutor(MultiThreadedExecutor):
    """MultiThreadedExecutor(num_threads) without the busy loop over Tasks already queued."""

    def __init__(self, num_threads: int | None = None, *, context=None):
        super().__init__(num_threads=num_threads, context=context)
        self._submitted: dict[object, PoolFuture] = {}
        self._finished = threading.Condition()
        self.requeue_waits = 0  # how often a queued Task was yielded again (and waited for)

    def _run(self, handler) -> None:
        try:
            handler()
        finally:
            with self._finished:
                self._finished.notify_all()

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False) -> None:
        try:
            handler, _, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException):
            return
        pending = self._submitted.get(handler)
        if pending is not None and not pending.done():
            self.requeue_waits += 1
            with self._finished:
                self._finished.wait(REQUEUED_WAIT_S)
        else:
            self._submitted[handler] = self._executor.submit(self._run, handler)
        for task in list(self._submitted):
            if task.done():
                del self._submitted[task]
                try:
                    task.result()  # raise any exception of the callback
                except Exception:
                    # a handler cut short by shutdown (its guard condition already destroyed) has
                    # nothing to report
                    if not self._is_shutdown:
                        raise


def result_within(future, timeout_s: float):
    """The result of an rclpy future that an executor spinning in another thread completes, waiting at
    most timeout_s (s); raises TimeoutError."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s):
        raise TimeoutError(f"no result within {timeout_s} s")
    return future.result()
