import threading
import time

from arm_ros.latest_worker import LatestWorker


def _wait_for(condition, timeout_s=5.0):
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.005)
    return condition()


def test_items_offered_while_busy_are_replaced_by_the_newest():
    started, release, done = threading.Event(), threading.Event(), []

    def process(item):
        started.set()
        release.wait(5.0)
        done.append(item)

    worker = LatestWorker(process, "test")
    assert not worker.offer(0)
    assert started.wait(5.0)  # 0 is being processed: 1 and 2 wait, 2 replaces 1
    assert not worker.offer(1)
    assert worker.offer(2)
    release.set()
    assert _wait_for(lambda: len(done) == 2)
    worker.close()
    assert done == [0, 2]


def test_offer_if_idle_queues_only_when_nothing_newer_waits():
    started, gate, done = threading.Event(), threading.Event(), []
    worker = LatestWorker(lambda item: (started.set(), gate.wait(5.0), done.append(item)), "test")
    worker.offer("busy")
    assert started.wait(5.0)
    assert worker.offer_if_idle("redo")
    assert not worker.offer_if_idle("older")  # "redo" waits
    gate.set()
    assert _wait_for(lambda: done == ["busy", "redo"])
    worker.close()


def test_an_item_waits_while_wait_s_says_so_and_starts_after_notify():
    hold, done = [True], []
    worker = LatestWorker(done.append, "test", wait_s=lambda: 10.0 if hold[0] else 0.0)
    worker.offer("frame")
    time.sleep(0.1)
    assert done == []
    hold[0] = False
    worker.notify()
    assert _wait_for(lambda: done == ["frame"])
    worker.close()


def test_close_stops_an_idle_worker_at_once():
    worker = LatestWorker(lambda item: None, "test")
    started = time.monotonic()
    worker.close()
    assert worker.stopping and time.monotonic() - started < 1.0
