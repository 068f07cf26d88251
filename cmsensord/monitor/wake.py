"""The board block whose frames complete the Processor's next output (the live loop wakes for it).

Live, the loop hands the Processor its frames as soon as the block completing the next output
is in: the next /orders block's last block (:meth:`OrderChain.next_output_sample
<cmsensord.monitor.orders.OrderChain.next_output_sample>`), or the last block of the next
decision period still to come, whichever is first.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.orders import OrderChain
    from cmsensord.monitor.severity import SeverityChain


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
