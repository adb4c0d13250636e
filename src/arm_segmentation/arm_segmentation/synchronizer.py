"""Approximate-time synchronization of several message streams (message_filters is unavailable).

Each input keeps a short queue of (stamp, item). After every arrival the synchronizer looks for
the newest set that has one item per input with all stamps within `slop_s` of each other; when it
finds one it returns it and forgets that set and everything older, so a consumer only ever sees
the latest complete frame and memory stays bounded. Items older than the last emitted set are
dropped as stale; a set sent again with the same stamps (a bag replay re-sending a frame that was
not consumed downstream) is emitted again.
"""

from collections import deque
from dataclasses import dataclass, field


@dataclass
class SyncStats:
    """Counters for diagnostics."""

    received: int = 0
    emitted: int = 0
    dropped_stale: int = 0
    per_input: list[int] = field(default_factory=list)


class ApproximateTimeSynchronizer:
    """Match items from `n_inputs` streams by timestamp (seconds) within `slop_s`."""

    def __init__(self, n_inputs: int, slop_s: float, queue_size: int = 5):
        if n_inputs < 1:
            raise ValueError("n_inputs must be >= 1")
        if not slop_s >= 0.0:
            raise ValueError("slop_s must be >= 0")
        if queue_size < 1:
            raise ValueError("queue_size must be >= 1")
        self.n_inputs = n_inputs
        self.slop_s = float(slop_s)
        self._queues = [deque(maxlen=queue_size) for _ in range(n_inputs)]
        self._last_emitted = [float("-inf")] * n_inputs
        self.stats = SyncStats(per_input=[0] * n_inputs)

    def reset(self) -> None:
        for q in self._queues:
            q.clear()
        self._last_emitted = [float("-inf")] * self.n_inputs

    def add(self, index: int, stamp_s: float, item):
        """Add one item; returns (stamps, items) of the newest complete set, or None."""
        if not 0 <= index < self.n_inputs:
            raise IndexError(f"input {index} out of range 0..{self.n_inputs - 1}")
        stamp_s = float(stamp_s)
        self.stats.received += 1
        self.stats.per_input[index] += 1
        if stamp_s < self._last_emitted[index]:
            self.stats.dropped_stale += 1
            return None
        queue = self._queues[index]
        if queue and stamp_s <= queue[-1][0]:
            # out-of-order arrival: keep the queue sorted by stamp
            entries = sorted([*queue, (stamp_s, item)], key=lambda e: e[0])
            queue.clear()
            queue.extend(entries[-queue.maxlen :])
        else:
            queue.append((stamp_s, item))
        match = self._best_match()
        if match is None:
            return None
        chosen = [self._queues[i][j] for i, j in enumerate(match)]
        for i, (stamp, _) in enumerate(chosen):
            self._last_emitted[i] = stamp
            q = self._queues[i]
            while q and q[0][0] <= stamp:
                q.popleft()
        self.stats.emitted += 1
        return [c[0] for c in chosen], [c[1] for c in chosen]

    def _best_match(self):
        if any(not q for q in self._queues):
            return None
        best, best_key = None, None
        pivots = {stamp for q in self._queues for stamp, _ in q}
        for pivot in pivots:
            choice = []
            for q in self._queues:
                j = min(range(len(q)), key=lambda k, q=q: abs(q[k][0] - pivot))
                choice.append(j)
            stamps = [self._queues[i][j][0] for i, j in enumerate(choice)]
            if max(stamps) - min(stamps) > self.slop_s:
                continue
            key = (min(stamps), max(stamps))
            if best_key is None or key > best_key:
                best, best_key = choice, key
        return best
