"""The Processor's RAW stage (a base of :class:`~cmsensord.monitor.processor.Processor`): RAW
frames -> blocks in m/s² (:mod:`.raw`) -> block RMS observations, the indicator intervals,
captures and the order chain (:mod:`.orders`, made with the first RAW blocks), in pieces each
after the TACHO frames in front of it; the TACHO frames -> shaft speed, then what waited for it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from cmsensord.monitor.figures import Stage
from cmsensord.monitor.raw import RawBlocks
from cmsensord.protocol import Frame

if TYPE_CHECKING:
    from cmsensord.monitor.orders import OrderChain

__all__ = ["RawStage", "PIECE_S"]

#: RAW blocks go through the chains in pieces of at most this many board seconds, each after the TACHO
#: frames in front of it: any read gives what small reads give (a wait for the speed lasts 10 s)
PIECE_S = 2.0


class RawStage(Stage):
    """RAW frames and the shaft speed through the chains (see the module docstring)."""

    _orders_refused: int | None

    if TYPE_CHECKING:
        def _board_channels(self, C: int) -> None: ...
        def _observe(self, t0: np.ndarray, vals: np.ndarray, max_slots: int = ...,
                     placed: Callable[[np.ndarray, np.ndarray], None] | None = None,
                     flat: np.ndarray | None = None) -> None: ...
        def _release_decisions(self, final: bool, bounded: bool = False) -> None: ...

    def _flush_raw(self, frames: Sequence[Frame], final: bool = False) -> None:
        """RAW blocks -> m/s² -> block RMS observations, and samples to the order chain."""
        self.raw.add(frames)
        ready, C, events = self.raw.ready(self.setup.status, final, self.clock)
        self._out(events)
        if not ready or not self.setup.ready(C):
            return
        self._board_channels(C)
        blocks, events = self.raw.blocks(ready, C, self.clock.block_len, self.setup.status, self.clock.stamp_ns)
        self._out(events)
        if blocks is None:
            return
        if not (self.shaft.waiting and self.shaft.ensure(self.status, self.clock)):
            self._raw_blocks(blocks)
            return
        for piece in blocks.pieces(max(1, round(PIECE_S * self.clock.fs) // self.clock.block_len)):
            if self.shaft.waits_before(start := int(piece.t0[0])):     # the TACHO frames in front of it first
                self._feed_tacho(before=start)
            self._raw_blocks(piece)

    def _raw_blocks(self, blocks: RawBlocks) -> None:
        """Converted RAW blocks through the chains: observations, indicators (each run on one time
        base waits in :attr:`held` until before the next decision: its records go out ahead of the
        decisions after them, however the stream was cut into calls), captures, orders."""
        orders = self._order_chain(int(blocks.t0[0]))     # made before the decisions the blocks release
        self._observe(blocks.t0, blocks.rms(), placed=self.held.placer(blocks), flat=blocks.flat_counts())
        if not self.held.rows:                  # the banks wait for no decision: nor do the indicators
            self._hand_over()
        if self.captures is not None:
            self._out(self.captures.raw(self.channels, blocks.t0,
                                        blocks.samples([ch.index for ch in self.channels]), self.clock.fs))
        if orders is not None:
            index = [ch.index for ch in orders.channels]
            y = blocks.samples(index)
            for a, b in blocks.runs():          # consecutive except across lost blocks
                self._out(orders.add_samples(int(blocks.t0[a]), y[a:b].reshape(-1, len(index))))

    def _order_chain(self, start: int) -> OrderChain | None:
        """The order chain of the vibration channels, created with the first RAW blocks, from board
        sample ``start`` on, and said at once (None while there is none to make)."""
        if self.orders is None:
            vib = tuple(ch for ch in self.channels if ch.kind != "microphone")
            if not (vib and self.cfg.orders.enabled and self.severity is not None
                    and self.shaft.ensure(self.status, self.clock)) or self._orders_refused == self.clock.fs:
                return None
            from cmsensord.monitor.orders import OrderChain  # scipy is loaded only for the raw chain
            try:
                self.orders = OrderChain(self.cfg, vib, self.shaft.tracker(), fs=self.clock.fs, clock=self.clock,
                                         uncovered=self.shaft.uncovered)
            except ValueError as exc:           # a rate the tracked orders do not fit in
                self._orders_refused = self.clock.fs
                self.event("config", None, f"order tracker not started at fs {self.clock.fs} Hz: {exc}")
                return None
            expect_lag = getattr(self.sink, "expect_lag", None)
            if expect_lag is not None:          # orders come seconds behind: the file's order waits
                expect_lag()
            self._out(self.orders.begin(start))
        return self.orders

    def _feed_tacho(self, end: bool = False, before: int | None = None) -> None:
        """TACHO frames (``before``: those in front of the first at or after that t0) -> shaft
        speed, then what waited for a final speed (at most as long as the speed gates allow,
        except at the ``end`` where the order chain drains anyway)."""
        fed = bool(self.shaft.waiting) and self.shaft.ensure(self.setup.status, self.clock)
        if fed:
            self._out(self.shaft.feed(self.clock, before))
        if self.orders is not None and (fed or not end):
            self._out(self.orders.release(bounded=not end))
        self.indicators.release()
        self._release_decisions(final=False, bounded=True)
