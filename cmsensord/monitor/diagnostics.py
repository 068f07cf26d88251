"""``/cm/diagnostics`` messages, and the stamps of what the daemon says about itself.

The Processor writes a diagnostics message with each decision, stamped as the decision. The live
loop writes one when no decision brought one for a while (the board unplugged or off, a stalled
link), and the daemon's own events (``stop``, the link's events) come when they happen, whatever
the stream does: those are stamped with the wall clock on the stream's time base
(:meth:`Diagnostics.wall_stamp`, :meth:`~cmsensord.monitor.clock.BlockClock.wall_stamp_ns`): during
an outage, when the end of the newest observation stands still, they go on at the time they are
written (diagnostics five seconds apart, ``stop`` when SIGTERM came).  A diagnostics message is
never stamped before the one written before it (a step of the wall clock moves that bound with
the time base).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from cmsensord.monitor import messages
from cmsensord.monitor.clock import BlockClock

__all__ = ["Diagnostics"]


class Diagnostics:
    """Diagnostics messages: the link's counters (``link``), the observations processed
    (``observations``), the uptime, and the live loop's figures (``extra``: queue, lag)."""

    def __init__(self, clock: BlockClock, clock_ns: Callable[[], int], link: Callable[[], dict],
                 observations: Callable[[], int], extra: Callable[[], dict] | None) -> None:
        self.clock, self.clock_ns = clock, clock_ns
        self.link, self.observations, self.extra = link, observations, extra
        self.started = self.at = time.monotonic()     # the start, and the newest message (monotonic s)
        self.newest_ns = 0                            # the newest message's stamp
        clock.steps.append(self.restepped)

    def message(self, stamp_ns: int) -> messages.Message:
        """A diagnostics message stamped ``stamp_ns``, or the newest one's stamp when that is later."""
        self.at = time.monotonic()
        stamp = self.newest_ns = max(stamp_ns, self.newest_ns)
        return messages.diagnostics(stamp, self.link(), self.observations(), round(self.at - self.started, 3),
                                    self.extra() if self.extra else None)

    def wall_stamp(self, wall_ns: int | None = None) -> int:
        """The stamp of what the daemon says at wall-clock time ``wall_ns`` (default: now)."""
        return self.clock.wall_stamp_ns(self.clock_ns() if wall_ns is None else wall_ns)

    def restepped(self, shift_ns: int) -> None:
        """The wall clock stepped: the newest stamp moves with the time base."""
        if self.newest_ns:
            self.newest_ns += shift_ns
