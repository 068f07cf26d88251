"""A Recording to a capture file (the bytes a board would send) and its sidecar JSON.

Frames go out as ``firmware_sim`` sends them (docs/PROTOCOL.md), through the
encoders of :mod:`cmsensord.protocol`: per block, a STATUS first when one is
due (block 0, then once a second of board time), then one RAW frame per channel
(RAW mode) or one RMS frame (RMS mode, the docs/PROTOCOL.md RMS of the block's
counts, as the board computes it), then a TACHO frame when a tacho is imported.
seq counts every frame; t0 is the block's first sample on the board clock,
which runs on continuously through the snapshots (:mod:`.blocks`). A block with
a sample at 0 or 4095 carries the clipped flag. A channel's block that holds a missing
sample (NaN) is not sent: its RAW frame (RMS mode: the block's RMS frame) is left out and
its seq skipped, as a frame the board lost, so a replay counts its observations missing.

The sidecar (``OUT.json``) holds what the frames cannot: the sources, the
channel names, the input unit and scale factor, the full-scale range, the
clipped blocks and samples per channel, ``rpm_differs`` (the files gave different speeds: a replay
does not use ``rpm``), each channel's mean taken out (``dc_removed``, over the
recording; null when kept; :mod:`.dc`), the speed (``rpm``, ``rpm_source``), the tacho
(``tacho``: the column's name or ``rpm``; ``tacho_from``: ``pulses``, ``speed`` or ``rpm``) and
the blocks left out for missing samples per channel (``missing_blocks``),
per snapshot its ``source`` (file, ``[i]`` for the i-th inside a file),
``start_s`` (board seconds), ``dc_removed`` (its own means, with several snapshots),
``length`` (samples in blocks), ``dropped``
(samples at its end that fill no block), ``pct_of_record`` (its start as a
percentage of the capture's board time), ``source_time_s`` (its start in the
original recording, when known, counted from ``source_start`` when its date is
known: the file names') and ``gap_before_s`` (from the previous snapshot's end to
its start there).

Counts are computed in vectorised chunks of at most ``CHUNK_BLOCKS`` blocks and
``CHUNK_SAMPLES`` samples (all channels), read from the recording's
:class:`~.samples.SampleStore`; only the frame encoding is per block. The capture is written to ``OUT.part`` and the
sidecar to ``OUT.json.part``; both are renamed when complete and deleted on any
error, so no partial capture is left behind.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from cmsensord.dsp.rms import block_rms
from cmsensord.protocol import (
    FLAG_CLIPPED,
    MODE_RAW,
    MODE_RMS,
    Status,
    encode_raw,
    encode_rms,
    encode_status,
    encode_tacho,
)

from .adc import ADC_MAX, HEADROOM, MAX_RANGE, OFFSET, nice_range, scale_for, to_counts
from .blocks import BlockPlan
from .dc import recording_means
from .errors import CHOOSE, ImportFailure, cannot_write
from .quantisation import LevelTally
from .recording import Recording
from .tacho import block_edges, rpm_edges
from .units import InG

__all__ = ["CHUNK_BLOCKS", "CHUNK_SAMPLES", "FW_VERSION", "MAX_TACHO_EDGES", "choose_ranges", "sidecar_path",
           "write_capture"]

CHUNK_BLOCKS = 1000
CHUNK_SAMPLES = 1 << 18
FW_VERSION = 0x0100
MAX_TACHO_EDGES = (4096 - 2) // 4  # edges one TACHO payload holds


def sidecar_path(out: str | Path) -> Path:
    return Path(f"{out}.json")


def choose_ranges(rec: Recording, requested: tuple[float, ...] | None) -> list[float]:
    """Full-scale range per channel, in its unit (m/s², a microphone's Pa): as given (one for all,
    or one each; a value given in g on a channel in Pa is a one-line error), else from the data."""
    C = rec.n_channels
    if requested:
        if len(requested) not in (1, C):
            raise ImportFailure(f"--range gives {len(requested)} values for {C} channels; give one, "
                                "or one per channel")
        ranges = requested * C if len(requested) == 1 else requested
        for name, unit, r in zip(rec.names, rec.units, ranges):
            if unit == "Pa" and isinstance(r, InG):
                raise ImportFailure(f"--range: {name} is a microphone's channel, in Pa: give its range in Pa, "
                                    "not in g (one per channel: --range 50g,20)")
        for r in ranges:
            if r > MAX_RANGE:
                raise ImportFailure(f"--range {r:g}: past the largest full scale the board's STATUS carries "
                                    f"(+-{MAX_RANGE:.3g}: its scale, a count's value, is a float32)")
        return [float(v) for v in ranges]
    for name, unit, peak in zip(rec.names, rec.units, rec.peak):
        if not peak <= MAX_RANGE / HEADROOM:
            raise ImportFailure(f"{name}: peak {peak:.4g} {unit}, past the largest full scale the board's STATUS "
                                f"carries (+-{MAX_RANGE:.3g} {unit}: its scale is a float32); check --unit and "
                                "--scale-factor, or a logger's no-value mark (1.8e308) in the file")
    return [nice_range(p) for p in rec.peak]


def _tacho_frames(rec: Recording, plan: BlockPlan) -> tuple[np.ndarray, np.ndarray] | None:
    if rec.tacho_edges is not None:
        pos = plan.to_board(rec, rec.tacho_edges)
    elif rec.tacho_source == "rpm" and rec.rpm:
        pos = rpm_edges(plan.n_board_samples, rec.fs, rec.rpm, rec.ppr)
    else:
        return None
    bounds, off = block_edges(pos, plan.block_len, plan.n_blocks)
    most = int(np.diff(bounds).max()) if plan.n_blocks else 0
    if most > MAX_TACHO_EDGES:
        what = (f"--rpm {rec.rpm:g}" if rec.tacho_edges is None else
                f"{Path(rec.sources[0]).name}: {'speed' if rec.tacho_from == 'speed' else 'tacho'} column "
                f"{rec.tacho_source!r}")
        raise ImportFailure(f"{what}: {most} edges in one {plan.block_len}-sample block, "
                            f"a TACHO frame holds at most {MAX_TACHO_EDGES}; check --tacho-threshold, "
                            "--ppr or --rpm")
    return bounds, off


def _frames(rec: Recording, plan: BlockPlan, mode: str, scale: np.ndarray, f,
            progress: Callable[[int], None] | None, tally: LevelTally | None) -> dict:
    """Encode and write every frame; returns the counts of frames, clipped blocks and samples;
    each block's level goes to ``tally``."""
    C, L, fs = rec.n_channels, plan.block_len, rec.fs
    offset = np.full(C, OFFSET)
    tacho = _tacho_frames(rec, plan)
    every = max(1, int(round(fs / L)))
    status = Status(fw_version=FW_VERSION, mode=MODE_RAW if mode == "raw" else MODE_RMS, n_channels=C,
                    fs=fs, block_len=L, tacho_inputs=int(tacho is not None), tacho_ppr=rec.ppr,
                    overruns=0, scale=tuple(scale.tolist()), offset=tuple(offset.tolist()), uptime_s=0)
    clip_blocks = np.zeros(C, dtype=np.int64)
    clip_samples = np.zeros(C, dtype=np.int64)
    missing_blocks = np.zeros(C, dtype=np.int64)
    seq = frames = 0
    ar = np.arange(L)
    snap_of = np.repeat(np.arange(len(rec.snapshots)), plan.snap_blocks)   # each block's snapshot
    chunk = max(1, min(CHUNK_BLOCKS, CHUNK_SAMPLES // (C * L)))
    for c0 in range(0, plan.n_blocks, chunk):
        c1 = min(c0 + chunk, plan.n_blocks)
        a0 = int(plan.src_start[c0])
        x = rec.samples.read(a0, int(plan.src_start[c1 - 1]) + L)
        xb = x[:, plan.src_start[c0:c1, None] - a0 + ar]  # (C, nb, L)
        if rec.dc is not None:                            # the offset taken out (.dc)
            xb -= rec.dc[snap_of[c0:c1]].T[:, :, None]
        lost = np.isnan(xb).any(axis=-1)  # (C, nb): a missing sample: the frame is not sent
        if lost.any():
            xb = np.where(np.isnan(xb), 0.0, xb)
            if mode == "rms":
                lost[:] = lost.any(axis=0)  # one RMS frame holds every channel's
        if tally is not None:
            tally.add(c0, xb, lost)
        counts = to_counts(xb, scale)
        edge = ((counts == 0) | (counts == ADC_MAX)) & ~lost[..., None]  # docs/PROTOCOL.md: clipped
        clip = edge.any(axis=-1)  # (C, nb)
        clip_blocks += clip.sum(axis=1)
        clip_samples += edge.sum(axis=(1, 2))
        missing_blocks += lost.sum(axis=1)
        if mode == "rms":
            rms = block_rms(counts.reshape(C, -1), scale, offset, L).T  # (nb, C)
            any_clip = clip.any(axis=0)
        parts = []
        for i in range(c1 - c0):
            b = c0 + i
            t0 = b * L
            if b % every == 0:
                parts.append(encode_status(seq, t0, dataclasses.replace(status, uptime_s=t0 // fs)))
                seq += 1
            if mode == "raw":
                for c in range(C):
                    if not lost[c, i]:
                        parts.append(encode_raw(seq, t0, c, counts[c, i], FLAG_CLIPPED if clip[c, i] else 0))
                    seq += 1
            else:
                if not lost[0, i]:
                    parts.append(encode_rms(seq, t0, rms[i], FLAG_CLIPPED if any_clip[i] else 0))
                seq += 1
            if tacho is not None:
                bounds, off = tacho
                parts.append(encode_tacho(seq, t0, 0, off[bounds[b]:bounds[b + 1]]))
                seq += 1
        frames += len(parts)
        f.write(b"".join(parts))
        if progress is not None:
            progress(c1)
    return {"frames": frames, "clipped_blocks": clip_blocks.tolist(),
            "clipped_samples": clip_samples.tolist(), "missing_blocks": missing_blocks.tolist(),
            "tacho_edges": int(tacho[1].size) if tacho is not None else 0}


def _sidecar(rec: Recording, plan: BlockPlan, mode: str, full_scale: list[float], scale: np.ndarray,
             stats: dict, out: str, extra: dict) -> dict:
    L, fs = plan.block_len, rec.fs
    total = max(plan.n_board_samples, 1)
    snaps = []
    prev_end = None
    for k, s in enumerate(rec.snapshots):
        start = int(plan.snap_board_start[k])
        gap = None
        if s.source_time_s is not None and prev_end is not None:
            gap = round(s.source_time_s - prev_end, 6)
        prev_end = None if s.source_time_s is None else s.source_time_s + s.length / fs
        snaps.append({"source": s.source, "start_s": start / fs,
                      "length": int(plan.snap_blocks[k] * L), "dropped": int(plan.dropped[k]),
                      "pct_of_record": round(100.0 * start / total, 4),
                      **({"dc_removed": [round(float(v), 9) for v in rec.dc[k]]}
                         if rec.dc is not None and len(rec.snapshots) > 1 else {}),
                      "source_time_s": None if s.source_time_s is None else round(s.source_time_s, 6),
                      "gap_before_s": gap})
    return {
        "format": "cmsensord import", "version": 1,
        "capture": Path(out).name, "sources": rec.sources, "mode": mode,
        "fs": fs, "block_len": L, "blocks_per_s": fs / L,
        "channel_names": rec.names, "unit": _one_or_each(rec.units),
        "source_unit": _one_or_each(rec.source_units or ["m/s2"]), **extra,
        "full_scale": full_scale, "scale": scale.tolist(), "offset": [OFFSET] * rec.n_channels,
        "dc_removed": [round(v, 9) for v in recording_means(rec)] if rec.dc is not None else None,
        "clipped_blocks": stats["clipped_blocks"], "clipped_samples": stats["clipped_samples"],
        "missing_blocks": stats["missing_blocks"],
        "board_seconds": plan.n_board_samples / fs, "blocks": plan.n_blocks, "frames": stats["frames"],
        "dropped_samples": int(plan.dropped.sum()),
        "rpm": rec.rpm, "rpm_source": rec.rpm_source, "rpm_differs": rec.rpm_differs, "ppr": rec.ppr,
        "tacho": rec.tacho_source if stats["tacho_edges"] or rec.tacho_source else None,
        "tacho_from": rec.tacho_from,
        "tacho_edges": stats["tacho_edges"],
        "source_start": rec.source_start,
        "snapshots": snaps,
    }


def write_capture(rec: Recording, plan: BlockPlan, out: str, *, mode: str = "raw",
                  full_scale: list[float], extra: dict | None = None,
                  progress: Callable[[int], None] | None = None, tally: LevelTally | None = None) -> dict:
    """Write ``out`` and ``out.json`` (the sidecar, also returned); nothing is left on error.
    ``tally``: the level of each block goes to it (:mod:`.quantisation`)."""
    scale = np.array([scale_for(r) for r in full_scale])
    part = Path(f"{out}.part")
    side = sidecar_path(out)
    side_part = Path(f"{side}.part")
    try:
        try:
            with open(part, "wb") as f:
                stats = _frames(rec, plan, mode, scale, f, progress, tally)
            _refuse_lost(rec, plan, stats["missing_blocks"])
            meta = _sidecar(rec, plan, mode, full_scale, scale, stats, out, extra or {})
            side_part.write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
            with _sigint_held():             # capture and sidecar renamed both, or neither
                os.replace(part, out)
                os.replace(side_part, side)
        except OSError as exc:
            raise cannot_write(out, exc.strerror or str(exc)) from None
    except BaseException:
        for p in (part, side_part):
            p.unlink(missing_ok=True)
        raise
    return meta


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """SIGINT held (blocked) for the block, delivered at its end: a Ctrl-C inside it comes after."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _refuse_lost(rec: Recording, plan: BlockPlan, missing_blocks: list[int]) -> None:
    """An ImportFailure when a channel lost every block to missing values (one NaN or inf in
    each): its capture would hold none of its samples."""
    lost = [name for name, n in zip(rec.names, missing_blocks) if plan.n_blocks and n == plan.n_blocks]
    if lost:
        kept = [name for name in rec.names if name not in lost]
        keep = f"import only {', '.join(kept)} ({CHOOSE})" if kept else "clean the file"
        raise ImportFailure(f"{', '.join(lost)}: a missing value (NaN, inf or empty) in every one of the "
                            f"{plan.n_blocks:,} block(s): no block of it could be written; {keep}")


def _one_or_each(units: list[str]) -> str | list[str]:
    """One unit when every channel has it, else one per channel (the sidecar's ``unit``)."""
    return units[0] if len(set(units)) == 1 else units
