"""Snapshots to board blocks: the block length, which samples fill blocks, the board clock.

The board clock runs on, continuous, through every snapshot: snapshot k's
blocks follow snapshot k-1's directly. A block never straddles two snapshots;
the samples at the end of a snapshot that do not fill a whole block are
dropped, and :func:`remainder_note` says how many and how to keep them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cmsensord.protocol import MAX_BLOCKS_PER_S, MAX_RAW_BLOCK

from .errors import ImportFailure
from .recording import Recording

__all__ = ["BlockPlan", "choose_block_len", "plan_blocks", "remainder_note"]


def choose_block_len(fs: int, requested: int | None, mode: str) -> tuple[int, str | None]:
    """(block_len, note): ``requested``, or round(fs / 100) so that 100 blocks make a second."""
    if requested is not None:
        L = int(requested)
        if not 1 <= L <= 0xFFFF:
            raise ImportFailure(f"--block-len {L}: must be 1..65535 samples")
        note = None
    else:
        L = max(1, int(round(fs / 100)))
        if L > 0xFFFF:
            raise ImportFailure(f"fs {fs} Hz: blocks of fs/100 = {L:,} samples, more than STATUS carries (65535); "
                                "give --block-len")
        note = None if fs % 100 == 0 else (
            f"block_len {L} (fs/100 = {fs / 100:g} is not whole): {fs / L:.3f} blocks per second")
    if mode == "raw" and L > MAX_RAW_BLOCK:
        raise ImportFailure(f"block_len {L}: a RAW frame carries at most {MAX_RAW_BLOCK} samples; "
                            f"give --block-len {MAX_RAW_BLOCK} or less, or use --mode rms")
    if fs > MAX_BLOCKS_PER_S * L:
        raise ImportFailure(f"block_len {L} at {fs} Hz: {fs / L:,.0f} blocks a second, more than the daemon takes "
                            f"({MAX_BLOCKS_PER_S:,}); give --block-len {-(-fs // MAX_BLOCKS_PER_S)} or more")
    return L, note


@dataclass(frozen=True)
class BlockPlan:
    block_len: int
    src_start: np.ndarray  # int64 (n_blocks,): first sample of each block in Recording.data
    snap_blocks: np.ndarray  # int64 (n_snapshots,): whole blocks in each snapshot
    snap_board_start: np.ndarray  # int64 (n_snapshots,): board sample index of each snapshot's start
    dropped: np.ndarray  # int64 (n_snapshots,): samples at its end that fill no block

    @property
    def n_blocks(self) -> int:
        return int(self.src_start.size)

    @property
    def n_board_samples(self) -> int:
        return self.n_blocks * self.block_len

    def to_board(self, rec: Recording, pos: np.ndarray) -> np.ndarray:
        """Fractional sample positions in ``rec.data`` to board sample positions (sorted);
        positions in dropped samples are left out."""
        starts = np.array([s.start for s in rec.snapshots], dtype=np.int64)
        k = np.searchsorted(starts, np.floor(pos), side="right") - 1
        rel = pos - starts[k]
        keep = rel < self.snap_blocks[k] * self.block_len
        return np.sort(self.snap_board_start[k[keep]] + rel[keep])


def plan_blocks(rec: Recording, block_len: int) -> BlockPlan:
    L = block_len
    lengths = np.array([s.length for s in rec.snapshots], dtype=np.int64)
    starts = np.array([s.start for s in rec.snapshots], dtype=np.int64)
    nb = lengths // L
    board_start = np.concatenate([[0], np.cumsum(nb)[:-1]]) * L
    src = np.repeat(starts, nb) + (np.arange(int(nb.sum())) - np.repeat(board_start // L, nb)) * L
    return BlockPlan(L, src, nb, board_start, lengths - nb * L)


def _divisor_near(n: int, target: float) -> int | None:
    best = None
    for d in range(max(1, int(target / 2)), min(MAX_RAW_BLOCK, int(target * 2)) + 1):
        if n % d == 0 and (best is None or abs(d - target) < abs(best - target)):
            best = d
    return best


def remainder_note(rec: Recording, plan: BlockPlan) -> str | None:
    """One line on the samples that fill no block, or None when every sample is in a block."""
    total = int(plan.dropped.sum())
    if not total:
        return None
    L = plan.block_len
    lengths = {s.length for s in rec.snapshots}
    hit = int((plan.dropped > 0).sum())
    pct = 100.0 * total / rec.n_samples
    if len(lengths) == 1:
        n = lengths.pop()
        d = _divisor_near(n, rec.fs / 100)
        rate = rec.fs / d if d else 100.0
        off = (f" ({rate:.4g} blocks a second, not 100: a replay's decision_rule warning says what that changes)"
               if abs(rate - 100.0) > 1.0 else "")
        fix = f"; --block-len {d} (a divisor of {n}) keeps them{off}" if d else ""
        what = "the recording" if len(rec.snapshots) == 1 else f"each {n}-sample snapshot"
        return (f"{what} ends with {n % L} sample(s) that do not fill a {L}-sample block: dropped "
                f"({total} samples in all, {pct:.2f} %){fix}")
    return (f"{hit} snapshot(s) end with samples that do not fill a {L}-sample block: dropped "
            f"({total} samples in all, {pct:.2f} %)")
