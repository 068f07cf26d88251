"""Messages into a file in log-time order: a reorder window that learns how late messages come.

The monitoring chain writes each message when it is computed, stamped with the
time of the data it is about. Most topics come in time order, but some lag
the others: in RAW mode with a tacho the order tracker's ``/orders`` wait for
the shaft speed and the smoother (up to ~6 s behind the decisions); with the
AKF trace of several channels, one channel's trace of a batch of frames comes
after the other's (up to ~1.3 s behind). MCAP
readers (``mcap doctor``, Foxglove's playback) want the messages of a file in
log-time order.

:class:`ReorderWindow` holds messages for a *horizon* H of stamp time: a
message is released once a message at least H newer has been pushed, or at
:meth:`drain` (the file's end). H starts at 0 (a stream in order passes
straight through: nothing is held, crash safety is unchanged) and grows to
the largest lateness seen (how far a message's stamp is behind the newest
stamp pushed before it), up to ``max_s`` (:data:`MAX_S`, 10 s). A message
later than what has already been released (before H has learnt the lag, or
more than ``max_s`` late) is released at once with ``log_time`` = the newest
released log time; its ``publish_time`` and its ``timestamp`` field keep its
own stamp, so log times never go back within a file and nothing is lost.
:attr:`ReorderWindow.clamped` counts these.

A *group* (:data:`GROUP` as its channel id, ``((channel_id, data), ...)`` as its data: the
three messages of a capture) is held and released as one entry, so no message of the file
comes between its messages.

At most ``max_held`` messages and ``max_bytes`` of them (8 MB) are held (the
oldest are released beyond it), so memory stays bounded whatever the stamps do.
"""

from __future__ import annotations

import heapq

__all__ = ["GROUP", "MAX_S", "Payload", "ReorderWindow"]

#: the longest a message is held (seconds of stamp time): the cap of the horizon
MAX_S = 10.0
_NS = 1_000_000_000
#: the channel id of a group entry, whose data is ``((channel_id, data), ...)``
GROUP = -1
#: a message's encoded data, or a group's messages
Payload = bytes | tuple[tuple[int, bytes], ...]


def _size(data: Payload) -> int:
    return len(data) if isinstance(data, bytes) else sum(len(d) for _, d in data)


class ReorderWindow:
    """A heap of ``(stamp, seq, channel_id, data)`` (a :data:`Payload`) released in stamp order."""

    def __init__(self, max_s: float = MAX_S, *, horizon_ns: int = 0, max_held: int = 200_000,
                 max_bytes: int = 8 << 20):
        self.max_ns = int(max_s * _NS)
        self.horizon_ns = min(int(horizon_ns), self.max_ns)
        self.max_held, self.max_bytes = max_held, max_bytes
        self._bytes = 0                # of the messages held
        self.clamped = 0
        self._heap: list[tuple[int, int, int, Payload]] = []
        self._seq = 0
        self._newest = -1          # newest stamp pushed
        self._released = -1        # newest log time released

    def hold_all(self) -> None:
        """Hold every message until :meth:`drain` (up to ``max_held``): for a writer of results
        that come after the whole run (``cmsensord vkf``)."""
        self.max_ns = self.horizon_ns = 1 << 62

    def __len__(self) -> int:
        return len(self._heap)

    @property
    def newest_ns(self) -> int:
        """The newest stamp pushed (-1 before the first)."""
        return self._newest

    def passes(self, stamp_ns: int) -> bool:
        """True when a message stamped ``stamp_ns`` goes straight through (nothing held, the
        horizon 0, in order): it is noted as released, as :meth:`push` notes it; False, and
        nothing noted, otherwise (the message is then to be pushed)."""
        if self.horizon_ns or self._heap or stamp_ns < self._newest or stamp_ns < self._released:
            return False
        self._newest = self._released = stamp_ns
        return True

    def push(self, stamp_ns: int, channel_id: int, data: Payload) -> list[tuple[int, int, int, Payload]]:
        """Add one message; returns the messages now due, each ``(log_time, publish_time,
        channel_id, data)``, in log-time order."""
        if stamp_ns < self._newest:
            late = self._newest - stamp_ns
            if late > self.horizon_ns:
                self.horizon_ns = min(late, self.max_ns)
        else:
            self._newest = stamp_ns
        if stamp_ns < self._released:            # its place is in the file already
            self.clamped += 1
            return [(self._released, stamp_ns, channel_id, data)]
        if not self._heap and stamp_ns >= self._newest - self.horizon_ns and self.horizon_ns == 0:
            self._released = stamp_ns            # in order and nothing held: straight through
            return [(stamp_ns, stamp_ns, channel_id, data)]
        self._seq += 1
        heapq.heappush(self._heap, (stamp_ns, self._seq, channel_id, data))
        self._bytes += _size(data)
        return self._due(self._newest - self.horizon_ns)

    def _due(self, upto_ns: int) -> list[tuple[int, int, int, Payload]]:
        out = []
        heap = self._heap
        while heap and (heap[0][0] <= upto_ns or len(heap) > self.max_held or self._bytes > self.max_bytes):
            stamp, _, channel_id, data = heapq.heappop(heap)
            self._bytes -= _size(data)
            self._released = max(self._released, stamp)
            out.append((stamp, stamp, channel_id, data))
        return out

    def drain(self) -> list[tuple[int, int, int, Payload]]:
        """Every message held, in log-time order (the end of a file)."""
        return self._due(1 << 63)
