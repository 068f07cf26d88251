"""The board's block clock: anchoring, unwrapped t0 -> slots and stamps, gaps, re-anchoring.

Timestamps come from the ADC clock (docs/PROTOCOL.md rule 4):
t = anchor + (t0_unwrapped - t0_first) / fs, the anchor being the wall clock
when the first frame was received.  Observations sit on slots of one block:
slot = (t0_unwrapped - slot0_t0) / block_len, slot 0 being the first
observation.  A slot with no frame is a *missing observation*; a jump of more
than ``MAX_GAP_S`` (or backwards) is a time jump (board reset, t0 reloaded)
and re-anchors the slots instead of inserting hours of missing observations.
"""

from __future__ import annotations

import numpy as np

DEFAULT_FS = 25000
DEFAULT_BLOCK_LEN = 250
#: a jump of the block clock larger than this (or backwards) is a time jump
MAX_GAP_S = 600.0


class BlockClock:
    """Slots and wall-clock stamps of the board's blocks (see module docstring)."""

    def __init__(self) -> None:
        self.fs = DEFAULT_FS
        self.block_len = DEFAULT_BLOCK_LEN
        self.anchor_ns: int | None = None      # wall clock at the first frame
        self.t0_first: int | None = None       # t0_unwrapped of the first frame
        self.slot0_t0: int | None = None       # t0_unwrapped of slot 0
        self.next_slot = 0                     # next observation slot expected
        self.last_stamp_ns = 0                 # stamp of the newest observation slot

    def anchor(self, t0_unwrapped: int, wall_ns: int) -> None:
        """The first frame: its t0 is ``wall_ns``."""
        if self.anchor_ns is None:
            self.anchor_ns = wall_ns
            self.t0_first = t0_unwrapped

    def set_rate(self, fs: int, block_len: int) -> bool:
        """The board's fs/block_len; True when the slots had to be re-anchored for it."""
        if fs <= 0 or block_len <= 0 or (fs, block_len) == (self.fs, self.block_len):
            return False
        moved = self.slot0_t0 is not None
        self.slot0_t0 = None
        self.fs, self.block_len = fs, block_len
        return moved

    # ---- stamps ------------------------------------------------------------
    def stamp_ns(self, t0_unwrapped: int) -> int:
        """ADC sample index -> ns since the epoch (docs/PROTOCOL.md rule 4)."""
        assert self.anchor_ns is not None and self.t0_first is not None
        return self.anchor_ns + (t0_unwrapped - self.t0_first) * 1_000_000_000 // self.fs

    def slot_t0(self, slot) -> int:
        assert self.slot0_t0 is not None
        return self.slot0_t0 + slot * self.block_len

    def slot_stamp_ns(self, slot: int) -> int:
        return self.stamp_ns(self.slot_t0(slot))

    @property
    def board_seconds(self) -> float:
        """The board's clock (t0_unwrapped / fs) at the end of the processed observations."""
        if self.slot0_t0 is None:
            return 0.0
        return (self.slot0_t0 + self.next_slot * self.block_len) / self.fs

    @property
    def adc_seconds(self) -> float:
        """ADC time covered by the observations processed so far."""
        return self.next_slot * self.block_len / self.fs

    # ---- slots -------------------------------------------------------------
    def place(self, t0: np.ndarray) -> tuple[np.ndarray, int]:
        """Slots of the blocks starting at ``t0`` (int64, in arrival order), up to the first
        time jump or duplicate: (slots of the first n blocks, n).  n < len(t0): call
        :meth:`reanchor` with t0[n], then place the rest."""
        if self.slot0_t0 is None:
            self.slot0_t0 = int(t0[0]) - self.next_slot * self.block_len
        slots = (t0 - self.slot0_t0) // self.block_len
        max_gap = int(MAX_GAP_S * self.fs / self.block_len)
        prev = np.concatenate(([self.next_slot - 1], slots[:-1]))
        bad = np.flatnonzero((slots <= prev) | (slots - prev > max_gap))
        n = int(bad[0]) if bad.size else len(t0)
        return slots[:n], n

    def reanchor(self, t0: int) -> None:
        """The block starting at ``t0`` takes the next slot."""
        self.slot0_t0 = t0 - self.next_slot * self.block_len

    def advance(self, n_slots: int) -> None:
        """``n_slots`` more observation slots are processed."""
        self.next_slot += n_slots
        self.last_stamp_ns = self.slot_stamp_ns(self.next_slot - 1)
