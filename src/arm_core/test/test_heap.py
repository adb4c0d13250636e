"""Freezing a process's start-up objects: later collections skip them, later garbage is still freed."""

import gc
import weakref

from arm_core.heap import freeze_startup_objects


class _Node:
    def __init__(self):
        self.partner = self  # a reference cycle: only the cyclic collector frees it


def test_frozen_objects_leave_the_scans_and_later_cycles_are_still_collected():
    try:
        startup = [_Node() for _ in range(1000)]
        assert freeze_startup_objects() >= len(startup)
        assert len(gc.get_objects()) < gc.get_freeze_count()
        later = _Node()
        gone = weakref.ref(later)
        del later
        gc.collect()
        assert gone() is None
    finally:
        gc.unfreeze()
