"""The share of RAW blocks that no output of a live call needs, held until one does.

Live, RAW with orders, the Processor is called ten times a second (once per /orders block),
but the anomaly decisions come once per decision period, and only once the tacho's speed
is final for it, and the indicator records only with the decisions.  So, between those, a
call's observations wait here instead of going through the AKF banks, and its blocks
instead of going into the indicator intervals: both take them in any number of parts with
the same results (a replay hands over seconds at once), so the Processor hands them over
joined when a decision may be due, or anything else needs them (a new segment, new channels,
a quiet link, the end).  What the slots' stamps depend on (the block clock) is not held.
Without orders every call's blocks pass through here too, handed over before the banks
take the call's observations, so the indicator records are there before the decisions
after them (a replay's call of seconds gives what the live calls give).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from cmsensord.dsp.severity import NOT_LOOKED
from cmsensord.monitor.raw import RawBlocks

if TYPE_CHECKING:
    from cmsensord.config import ChannelConfig
    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.indicators import Indicators
    from cmsensord.monitor.severity import SeverityChain

#: most slots held (then handed over whatever waits): bounds the memory, ~10 s at 100 blocks a second
MAX_HELD_SLOTS = 1000


class Held:
    """Observation rows (first slot, y, valid, flat counts or None) for the banks and RAW
    blocks for the indicators, in order, until :meth:`take_rows` and :meth:`take_blocks`."""

    def __init__(self) -> None:
        self.rows: list[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]] = []
        self.blocks: list[RawBlocks] = []
        self.n_rows = 0

    def __bool__(self) -> bool:
        return bool(self.rows or self.blocks)

    def full(self) -> bool:
        return self.n_rows >= MAX_HELD_SLOTS

    def add_rows(self, first: int, y: np.ndarray, valid: np.ndarray, flat: np.ndarray | None = None) -> None:
        """Observations (T, C) of the slots ``first``.. (following those held), and the counts of
        their flat blocks (NaN: not flat; None: not looked for)."""
        assert not self.rows or self.rows[-1][0] + len(self.rows[-1][1]) == first, "slots in order"
        self.rows.append((first, y, valid, flat))
        self.n_rows += len(y)

    def decision_due(self, sev: SeverityChain, tacho: TachoTracker, clock: BlockClock, bounded: bool) -> bool:
        """Whether a release may bring a decision: the tacho covers the waiting period's last
        slot (its speed cannot be final before), or the gate (with the rows held here) is over
        its bound, or this is full.  Else a release of part of a period decides nothing (the
        decider takes a period in any parts) and would have the tacho fit its smoothed speed."""
        gate = sev.gate
        waiting = gate.waiting + self.n_rows        # the held rows follow the gate's
        if (bounded and waiting > gate.max_rows) or clock.slot0_t0 is None or self.n_rows >= MAX_HELD_SLOTS:
            return True
        first = gate.first
        last = first + sev.decider.period - sev.decider.phase - 1     # the period's last slot
        return last < first + waiting and tacho.covered_until >= clock.slot_t0(last + 1)

    def hand_over(self, sev: SeverityChain | None, indicators: Indicators,
                  channels: tuple[ChannelConfig, ...]) -> None:
        """What is held to the banks and the indicator intervals (before anything reads them, or
        changes the channels or the time segment)."""
        rows = self.take_rows()
        if rows is not None:
            assert sev is not None
            first, y, valid, flat = rows
            sev.observe(first, y, valid, flat=flat)
        blocks = self.take_blocks()
        if blocks is not None:
            indicators.raw(channels, blocks)

    def placer(self, blocks: RawBlocks) -> Callable[[np.ndarray, np.ndarray], None]:
        """A ``placed`` callback of the Processor's ``_observe``: holds ``blocks`` run by run as
        the block clock places them (each call's ``t0`` are the next of them)."""
        start = 0

        def placed(t0: np.ndarray, _vals: np.ndarray) -> None:
            nonlocal start
            self.blocks.append(blocks.take(start, start + len(t0)))
            start += len(t0)
        return placed

    def take_rows(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray | None] | None:
        """The rows held, joined (None: none); their flat counts :data:`NOT_LOOKED` where a part
        has none."""
        rows, self.rows, self.n_rows = self.rows, [], 0
        if not rows:
            return None
        if len(rows) == 1:
            return rows[0]
        flat = None if all(r[3] is None for r in rows) else \
            np.concatenate([np.full(r[1].shape, NOT_LOOKED) if r[3] is None else r[3] for r in rows])
        return rows[0][0], np.concatenate([r[1] for r in rows]), np.concatenate([r[2] for r in rows]), flat

    def take_blocks(self) -> RawBlocks | None:
        """The blocks held, joined in one :class:`RawBlocks` (None: none)."""
        blocks, self.blocks = self.blocks, []
        if not blocks:
            return None
        return blocks[0] if len(blocks) == 1 else join_blocks(blocks)


def join_blocks(parts: list[RawBlocks]) -> RawBlocks:
    """RawBlocks of the same board channel count, one after the other, as one."""
    C = parts[0].n_channels
    assert all(p.n_channels == C for p in parts), "one channel count"
    offsets = np.cumsum([0] + [len(p.t0) for p in parts[:-1]])
    flat = None if any(p.flat is None for p in parts) else np.concatenate([p.flat for p in parts])
    return RawBlocks(np.concatenate([p.t0 for p in parts]),
                     np.concatenate([p.row + k for p, k in zip(parts, offsets.tolist())]),
                     np.concatenate([p.chan for p in parts]),
                     np.concatenate([p.x for p in parts]), C, flat)
