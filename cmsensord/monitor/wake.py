"""The board block whose frames complete the Processor's next output (the live loop wakes for it).

Live, the loop hands the Processor its frames as soon as the block completing the next output
is in: the next /orders block's last block (:meth:`OrderChain.next_output_sample
<cmsensord.monitor.orders.OrderChain.next_output_sample>`), or the last block of the next
decision period still to come, whichever is first.

A replay hands the Processor reads of thousands of frames; where what it writes depends on the
cut (an AKF trace or a microphone's estimates, written per slot ahead of the decisions; captures,
completed by the samples after their trigger, and the events they hold back), a run of RMS
frames goes through the chain in the pieces the live loop would hand it (:func:`output_pieces`),
so a replay writes its messages in the order, and with the log times, of a live run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.orders import OrderChain
    from cmsensord.monitor.severity import SeverityChain

#: a piece of :func:`output_pieces` with no output known ahead spans less than this much board
#: time (as the live loop's parts, ``source.BATCH_S``)
SPAN_S = 0.1


def wake_t0(clock: BlockClock, orders: OrderChain | None, sev: SeverityChain | None) -> int | None:
    """t0 of the board block whose frames complete the next output (None: none known); a
    decision waiting for the tacho is not one whose block is to come."""
    s0, L = clock.slot0_t0, clock.block_len
    if s0 is None:
        return None
    s = orders.next_output_sample() if orders is not None else None
    wake = None if s is None else s - (s - s0) % L
    if sev is not None and sev.gate.end is not None:
        last = sev.gate.first + sev.decider.period - sev.decider.phase - 1
        if last >= clock.next_slot:
            t0 = clock.slot_t0(last)
            wake = t0 if wake is None else min(wake, t0)
    return wake


def output_pieces(t0: np.ndarray, wake: Callable[[], int | None], span: int) -> Iterator[tuple[int, int]]:
    """Index ranges ``[a, b)`` of the blocks starting at ``t0`` to hand the chain one after the
    other, as the live loop cuts its batches (``output_parts`` in :mod:`cmsensord.service.live`):
    each ends with the block completing the next output (``wake()``, asked again after each piece
    is handled) or, with none known ahead, spans less than ``span`` board samples; a t0 stepping
    back ends a piece.  Each piece holds at least one block."""
    a, n = 0, len(t0)
    while a < n:
        first, at = int(t0[a]), wake()
        limit = first + span - 1 if at is None or at < first else at
        rest = t0[a:]
        over = (rest > limit) | (rest < first)
        b = a + max(1, int(over.argmax()) if over.any() else n - a)
        yield a, b
        a = b
