"""One worker thread that processes the newest item offered to it, for a node whose work per message
takes longer than the messages' period.

The executor's callbacks only offer items (a decoded frame, a complete set of camera messages) and
return, so the executor keeps taking messages from DDS while the worker is busy: an item that arrives
while another waits replaces it, and the worker starts on the newest one the moment it is free. Done
in the callback instead, the executor takes nothing while a frame is processed, and a subscription
that keeps only its newest message leaves the next set to be completed by later arrivals.
"""

import threading
from collections.abc import Callable


class LatestWorker:
    """process(item) runs in a daemon thread on the newest item offered.

    wait_s() -> seconds until the next item may start (<= 0: now), asked again at least whenever
    notify() is called and whenever it said to wait; its default never waits."""

    def __init__(self, process: Callable[[object], None], name: str, wait_s: Callable[[], float] = lambda: 0.0):
        self._process, self._wait_s = process, wait_s
        self._latest = None
        self._has_item = False
        self._wake = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    @property
    def stopping(self) -> bool:
        return self._stop

    def offer(self, item) -> bool:
        """Queue item as the next to process; True when it replaced one that was still waiting."""
        with self._wake:
            replaced = self._has_item
            self._latest, self._has_item = item, True
            self._wake.notify()
        return replaced

    def offer_if_idle(self, item) -> bool:
        """Queue item only when nothing newer waits (an item whose processing was abandoned, to be
        redone); True when it was queued."""
        with self._wake:
            if self._has_item:
                return False
            self._latest, self._has_item = item, True
            self._wake.notify()
        return True

    def notify(self) -> None:
        """Ask wait_s() again (what it depends on changed)."""
        with self._wake:
            self._wake.notify()

    def _work(self) -> None:
        while True:
            with self._wake:
                while not self._stop and (not self._has_item or self._wait_s() > 0):
                    self._wake.wait(self._wait_s() if self._has_item else None)
                if self._stop:
                    return
                item, self._latest, self._has_item = self._latest, None, False
            self._process(item)

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the thread; an item still being processed after timeout_s is abandoned (the thread is
        a daemon)."""
        with self._wake:
            self._stop = True
            self._wake.notify()
        self._thread.join(timeout=timeout_s)
