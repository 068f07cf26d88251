"""The simulated EK-TM4C1294XL ADC board: ADC, block RMS, tacho capture and framing.

Owns what the board's firmware does to a :class:`~firmware_sim.scenarios.Scenario`'s
acceleration (Kim et al. 2023, section IV: 25 kHz sampling, the RMS of each 250-sample
block sent at 100 Hz over the UART) and the exact bytes it sends (docs/PROTOCOL.md):

* ADC: ``count = clip(round(x / scale + offset), 0, 4095)`` per channel, 12 bit;
  a block in which a sample sits at 0 or 4095 carries ``FLAG_CLIPPED``;
* RMS (docs/PROTOCOL.md, RMS): ``sqrt(mean(((count - offset) * scale)^2))`` over the
  block, in float64, sent as float32, with nothing removed;
* tacho: rising edges where the shaft angle (the integral of the scenario's
  ``shaft_hz``) passes a multiple of 1/ppr revolution, as offsets from the
  block's t0 in 1/256 sample (a timer capture); optional encoder faults
  (``tacho_missed``, ``tacho_extra``, ``tacho_jitter``) drawn per pulse from
  ``SeedSequence([seed, TACHO_STREAM, m // 4096])``, so they are deterministic
  per seed and independent of chunking;
* framing, only through the encoders of :mod:`cmsensord.protocol`: STATUS at
  boot (block 0) and every ``status_every_s``, then per block the RMS frame (RMS
  mode) or one RAW frame per channel (RAW mode), then a TACHO frame when a
  tacho is wired; seq +1 for every frame (u16 wrap), t0 = the sample index of
  the block's first sample (u32 wrap);
* the link's byte budget (:func:`link_budget`, docs/PROTOCOL.md's table): whether a
  UART at a given baud rate carries the stream.

Samples are produced in vectorised chunks of ``chunk_blocks`` blocks (100, one
second, aligned with the scenario's 1-s segments); only the frame encoding is
per block.

STATUS ``scale``/``offset`` travel as float32, so the board works with the
float32-rounded values throughout (the daemon's recomputation from RAW with the
STATUS values then matches the RMS frames). ``t0_start`` presets the sample
counter (a board that has been up for a while: e.g. 2**32 - 1000 to cross the
u32 wrap soon); the scenario still starts at its t = 0, and the STATUS uptime
is ``(t0_start + sample index) // fs``.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cmsensord.dsp.rms import block_rms
from cmsensord.protocol import (
    FLAG_CLIPPED,
    FLAG_OVERRUN,
    MAX_PAYLOAD,
    MODE_RAW,
    MODE_RMS,
    OVERHEAD,
    Status,
    encode_raw,
    encode_rms,
    encode_status,
    encode_tacho,
)

from .scenarios.base import FULL_SCALE_MS2, Scenario
from .scenarios.noise import gauss, generator

__all__ = ["ADC_MAX", "BoardConfig", "Board", "TACHO_STREAM", "link_budget", "link_streams",
           "DEFAULT_BAUD"]

ADC_MAX = 4095  # 12-bit ADC
_SUB = 256  # tacho edge resolution: 1/256 sample
_U32 = 1 << 32
#: ``SeedSequence([seed, TACHO_STREAM, m // _TACHO_DRAW_BLOCK])`` seeds the encoder
#: faults of pulses m (the scenario's seed; streams 0..8 are channels, 1 << 16 the machine)
TACHO_STREAM = (1 << 16) + 1
_TACHO_DRAW_BLOCK = 4096
_EXTRA_FRAC = (0.3, 0.7)  # a spurious pulse lies this far into the pulse interval (angle)
_JITTER_TRUNC = 4.3  # the Gaussian table is truncated at +-4.3 sigma


@dataclass
class BoardConfig:
    """How the board is set up; ``scale``/``offset`` default to +-20 g full scale.

    ``overrun_blocks``: block indices at which the simulated ADC reports an
    overrun (FLAG_OVERRUN on that block's first data frame; the STATUS counter
    includes it from the next STATUS on). The data itself is unaffected.
    """

    mode: str = "rms"
    n_channels: int = 1
    fs: int = 25000
    block_len: int = 250
    scale: tuple[float, ...] | None = None  # m/s^2 per count; default FULL_SCALE_MS2*2/4096
    offset: tuple[float, ...] | None = None  # counts at 0 m/s^2; default 2048.0
    t0_start: int = 0
    seq_start: int = 0
    tacho: bool = False
    ppr: int = 1
    fw_version: int = 0x0100
    status_every_s: float = 1.0
    overrun_blocks: tuple[int, ...] = ()
    # block indices whose frames the board sends twice, at once (a DMA buffer sent again), under
    # their seqs, or (resend_new_seq) under the next seqs (the buffer sent again with a fresh header)
    resent_blocks: tuple[int, ...] = ()
    resend_new_seq: bool = False
    # shaft-encoder faults (see Board.tacho_edges): a probability per pulse, or the
    # pulse indices m (edge where ppr * turns = m, m = 0 at t = 0) to hit
    tacho_missed: float | tuple[int, ...] = 0.0  # pulses not seen
    tacho_extra: float | tuple[int, ...] = 0.0  # spurious pulse after pulse m
    tacho_jitter: float = 0.0  # std of the edge-time jitter, samples

    @staticmethod
    def _fault_spec(name: str, v) -> float | tuple[int, ...]:
        if isinstance(v, (list, tuple, np.ndarray)):
            idx = tuple(int(i) for i in v)
            if any(i < 0 for i in idx) or any(i != j for i, j in zip(idx, v)):
                raise ValueError(f"{name}: pulse indices must be non-negative integers, got {v!r}")
            return tuple(sorted(set(idx)))
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not 0.0 <= float(v) < 1.0:
            raise ValueError(f"{name} must be a probability in [0, 1) or a tuple of pulse indices, "
                             f"got {v!r}")
        return float(v)

    def __post_init__(self) -> None:
        self._check_sampling()
        self._set_calibration()
        self._check_header_fields()
        self.overrun_blocks = tuple(int(b) for b in self.overrun_blocks)
        self.resent_blocks = tuple(int(b) for b in self.resent_blocks)
        self.tacho_missed = self._fault_spec("tacho_missed", self.tacho_missed)
        self.tacho_extra = self._fault_spec("tacho_extra", self.tacho_extra)
        if not (self.tacho_jitter >= 0 and math.isfinite(self.tacho_jitter)):
            raise ValueError(f"tacho_jitter must be >= 0 samples, got {self.tacho_jitter!r}")
        self.tacho_jitter = float(self.tacho_jitter)

    def _check_sampling(self) -> None:
        """Mode, channels, sampling rate and block length: ValueError naming the field."""
        if self.mode not in ("rms", "raw"):
            raise ValueError(f"mode must be 'rms' or 'raw', got {self.mode!r}")
        if not isinstance(self.n_channels, int) or not 1 <= self.n_channels <= 8:
            raise ValueError(f"n_channels must be an integer 1..8, got {self.n_channels!r}")
        if not isinstance(self.fs, int) or self.fs <= 0:
            raise ValueError(f"fs must be a positive integer, got {self.fs!r}")
        if not isinstance(self.block_len, int) or not 1 <= self.block_len <= 0xFFFF:
            raise ValueError(f"block_len must be an integer 1..65535, got {self.block_len!r}")
        if self.mode == "raw" and 2 * self.block_len > MAX_PAYLOAD:
            raise ValueError(f"RAW blocks carry at most {MAX_PAYLOAD // 2} samples, block_len={self.block_len}")

    def _set_calibration(self) -> None:
        """Per-channel scale and offset (defaults: full scale over 12 bits, mid-range): as float tuples."""
        if self.scale is None:
            self.scale = (FULL_SCALE_MS2 * 2 / 4096.0,) * self.n_channels
        if self.offset is None:
            self.offset = (2048.0,) * self.n_channels
        self.scale = tuple(float(v) for v in self.scale)
        self.offset = tuple(float(v) for v in self.offset)
        if len(self.scale) != self.n_channels or len(self.offset) != self.n_channels:
            raise ValueError(f"scale and offset need {self.n_channels} values (one per channel), "
                             f"got {len(self.scale)} and {len(self.offset)}")
        if not all(v > 0 and math.isfinite(v) for v in self.scale):
            raise ValueError(f"scale values must be positive, got {self.scale}")
        if not all(0.0 <= v <= ADC_MAX for v in self.offset):
            raise ValueError(f"offset values must lie in 0..{ADC_MAX} counts, got {self.offset}")

    def _check_header_fields(self) -> None:
        """Start values and STATUS fields that must fit the frame header and payload."""
        if not isinstance(self.t0_start, int) or self.t0_start < 0:
            raise ValueError(f"t0_start must be a non-negative integer, got {self.t0_start!r}")
        if not isinstance(self.seq_start, int) or not 0 <= self.seq_start <= 0xFFFF:
            raise ValueError(f"seq_start must be an integer 0..65535, got {self.seq_start!r}")
        if not isinstance(self.ppr, int) or not 1 <= self.ppr <= 255:
            raise ValueError(f"ppr must be an integer 1..255, got {self.ppr!r}")
        if not 0 <= self.fw_version <= 0xFFFF:
            raise ValueError(f"fw_version must fit in u16, got {self.fw_version!r}")
        if not self.status_every_s > 0:
            raise ValueError(f"status_every_s must be > 0, got {self.status_every_s!r}")

    @property
    def tacho_faults(self) -> bool:
        """True when any shaft-encoder fault is configured."""
        return bool(self.tacho_missed) or bool(self.tacho_extra) or self.tacho_jitter > 0


class Board:
    """The board sampling ``scenario`` as set up by ``config``."""

    chunk_blocks = 100  # blocks rendered per vectorised step (1 s at 100 blocks/s)

    def __init__(self, scenario: Scenario, config: BoardConfig | None = None):
        config = config if config is not None else BoardConfig(
            n_channels=scenario.n_channels, fs=scenario.fs,
            scale=getattr(scenario, "board_scale", None))     # a microphone channel: Pa per count
        if scenario.n_channels != config.n_channels:
            raise ValueError(f"the scenario has {scenario.n_channels} channels, the board config "
                             f"{config.n_channels}")
        if scenario.fs != config.fs:
            raise ValueError(f"the scenario is sampled at {scenario.fs} Hz, the board at {config.fs} Hz")
        self.scenario = scenario
        self.config = config
        self.n_channels = config.n_channels
        self.fs = config.fs
        self.block_len = config.block_len
        # what STATUS carries (float32), used for every computation
        self.scale = np.asarray(config.scale, dtype=np.float32).astype(np.float64)
        self.offset = np.asarray(config.offset, dtype=np.float32).astype(np.float64)
        self._overrun_set = frozenset(config.overrun_blocks)
        self._resent_set = frozenset(config.resent_blocks)
        self._status_every = max(1, int(round(config.status_every_s * self.fs / self.block_len)))
        self._tacho_draw_cache: dict[int, dict[str, np.ndarray]] = {}

    # -- the ADC and the firmware's arithmetic ----------------------------------
    def counts(self, start: int, n: int) -> np.ndarray:
        """ADC counts, uint16 (C, n), of sample indices [start, start + n)."""
        x = self.scenario.samples(start, n)
        x /= self.scale[:, None]
        x += self.offset[:, None]
        np.rint(x, out=x)
        np.clip(x, 0, ADC_MAX, out=x)
        return x.astype(np.uint16)

    def _block_rms(self, counts: np.ndarray) -> np.ndarray:
        """float32 (C, nb): docs/PROTOCOL.md RMS of each block of ``counts`` (C, nb * block_len),
        by the same function the daemon applies to RAW blocks (cmsensord.dsp.rms)."""
        return block_rms(counts, self.scale, self.offset, self.block_len)

    def rms_block_values(self, counts: np.ndarray) -> np.ndarray:
        """float32 (C,): the RMS frame values of one block of counts, shape (C, block_len)."""
        counts = np.asarray(counts)
        if counts.shape != (self.n_channels, self.block_len):
            raise ValueError(f"expected counts of shape {(self.n_channels, self.block_len)}, "
                             f"got {counts.shape}")
        return self._block_rms(counts)[:, 0]

    def _block_clipped(self, counts: np.ndarray) -> np.ndarray:
        """bool (C, nb): a sample of the block sits at 0 or 4095."""
        c, n = counts.shape
        b = counts.reshape(c, n // self.block_len, self.block_len)
        return ((b == 0) | (b == ADC_MAX)).any(axis=-1)

    def tacho_edges(self, start_block: int, n_blocks: int) -> tuple[np.ndarray, np.ndarray]:
        """Rising tacho edges of blocks [start_block, start_block + n_blocks).

        Returns (block index, offset from the block's t0 in 1/256 sample (uint32)),
        in time order. An edge is where ``ppr * shaft_turns`` reaches an integer m
        (pulse m; pulse 0 is at t = 0); the sample interval [i, i + 1) with
        P(i) <= m < P(i + 1) holds it, at i + (m - P(i)) / (P(i + 1) - P(i))
        (linear within one sample), truncated to 1/256 sample (the capture
        timer's tick). Encoder faults (BoardConfig), per pulse m:

        * ``tacho_missed``: pulse m is not seen;
        * ``tacho_extra``: a spurious pulse where ``ppr * turns`` reaches
          m + f, f uniform in [0.3, 0.7] (drawn per m), i.e. inside the pulse
          interval after pulse m (not jittered);
        * ``tacho_jitter``: the edge time of pulse m moves by ``tacho_jitter`` x
          N(0, 1) samples (truncated at 4.3 sigma); an edge jittered before
          sample 0 is lost, one jittered across a block boundary is sent with
          the block it lands in.

        Each draw belongs to the pulse, not to the request, so the edges never
        depend on how the blocks are chunked.
        """
        q, _, _ = self._tacho_pulses(start_block, n_blocks)
        L = self.block_len
        blk, off = np.divmod(q, L * _SUB)
        return blk, off.astype(np.uint32)

    def tacho_pulses(self, start_block: int, n_blocks: int) -> dict[str, np.ndarray]:
        """What the encoder did in blocks [start_block, start_block + n_blocks) (for tests).

        ``edges``: int64 edge times in 1/256 sample from sample 0 (what
        :meth:`tacho_edges` sends); ``pulse``: the pulse index m of each edge
        (for a spurious edge, the pulse it follows); ``extra``: bool, spurious;
        ``missed``: pulse indices whose (unjittered) edge falls in the range and
        was dropped.
        """
        q, m, extra = self._tacho_pulses(start_block, n_blocks)
        _, missed = self._tacho_pulses(start_block, n_blocks, missed_only=True)
        return {"edges": q, "pulse": m, "extra": extra, "missed": missed}

    def _tacho_draws(self, m: np.ndarray) -> dict[str, np.ndarray]:
        """The per-pulse fault draws of pulse indices m (int64 >= 0)."""
        B = _TACHO_DRAW_BLOCK
        out = {k: np.empty(m.size) for k in ("miss", "extra", "frac", "jit")}
        kb = m // B
        for k in np.unique(kb):
            d = self._tacho_draw_cache.get(int(k))
            if d is None:
                rng = generator(self.scenario.seed, TACHO_STREAM, int(k))
                d = {"miss": rng.random(B), "extra": rng.random(B),
                     "frac": rng.uniform(*_EXTRA_FRAC, B), "jit": gauss(rng, B)}
                self._tacho_draw_cache[int(k)] = d
                while len(self._tacho_draw_cache) > 4:
                    self._tacho_draw_cache.pop(next(iter(self._tacho_draw_cache)))
            sel = kb == k
            for key in out:
                out[key][sel] = d[key][m[sel] - k * B]
        return out

    @staticmethod
    def _hit(spec: float | tuple[int, ...], m: np.ndarray, u: np.ndarray) -> np.ndarray:
        if isinstance(spec, tuple):
            return np.isin(m, np.asarray(spec, dtype=np.int64))
        return u < spec

    def _tacho_pulses(self, start_block: int, n_blocks: int, missed_only: bool = False):
        cfg = self.config
        L = self.block_len
        i0 = start_block * L
        n = n_blocks * L
        jit = cfg.tacho_jitter
        margin = int(math.ceil(_JITTER_TRUNC * jit)) + 1 if jit > 0 else 0
        a = max(i0 - margin, 0)
        b = i0 + n + margin
        idx = np.arange(a, b + 1, dtype=np.int64)
        p = cfg.ppr * self.scenario.shaft_turns(idx / self.fs)

        def locate(level: np.ndarray) -> np.ndarray:
            """1/256-sample times (int64, from sample 0) where p reaches ``level`` (in [p[0], p[-1]))."""
            rel = np.searchsorted(p, level, side="right") - 1
            rel = np.clip(rel, 0, p.size - 2)
            frac = (level - p[rel]) / (p[rel + 1] - p[rel])
            q = rel * _SUB + np.floor(frac * _SUB).astype(np.int64)
            return np.clip(q, rel * _SUB, rel * _SUB + _SUB - 1) + a * _SUB

        m = np.arange(math.ceil(p[0]), math.ceil(p[-1]), dtype=np.int64)  # p[0] <= m < p[-1]
        m = m[m >= 0]
        lo_q, hi_q = i0 * _SUB, (i0 + n) * _SUB
        if not cfg.tacho_faults:
            if missed_only:
                return None, np.empty(0, dtype=np.int64)
            q = locate(m.astype(np.float64))
            sel = (q >= lo_q) & (q < hi_q)
            return q[sel], m[sel], np.zeros(int(sel.sum()), dtype=bool)
        draws = self._tacho_draws(m)
        q = locate(m.astype(np.float64))
        missed = self._hit(cfg.tacho_missed, m, draws["miss"])
        if missed_only:
            sel = missed & (q >= lo_q) & (q < hi_q)
            return None, m[sel]
        if jit > 0:
            shift = np.floor(jit * draws["jit"] * _SUB).astype(np.int64)
            q = q + shift
        keep = ~missed
        q, m_real = q[keep], m[keep]
        # spurious pulses after pulse me, at level me + f
        me = np.arange(max(math.floor(p[0]) - 1, 0), max(math.ceil(p[-1]), 0), dtype=np.int64)
        de = self._tacho_draws(me)
        hit = self._hit(cfg.tacho_extra, me, de["extra"])
        level = me + de["frac"]
        ok = hit & (level >= p[0]) & (level < p[-1])
        me = me[ok]
        qe = locate(level[ok])
        q_all = np.concatenate([q, qe])
        m_all = np.concatenate([m_real, me])
        extra = np.concatenate([np.zeros(q.size, dtype=bool), np.ones(qe.size, dtype=bool)])
        sel = (q_all >= max(lo_q, 0)) & (q_all < hi_q)
        q_all, m_all, extra = q_all[sel], m_all[sel], extra[sel]
        order = np.lexsort((extra, q_all))
        return q_all[order], m_all[order], extra[order]

    # -- observations without framing ------------------------------------------------
    def observations(self, n_blocks: int, start_block: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(t0 int64 (n_blocks,), rms float32 (n_blocks, C)): what the RMS frames carry.

        t0 is the unwrapped sample index ``t0_start + block * block_len`` (the wire
        carries it mod 2^32, the decoder's ``t0_unwrapped`` restores it).
        """
        n_blocks, start_block = int(n_blocks), int(start_block)
        if n_blocks < 0 or start_block < 0:
            raise ValueError(f"n_blocks and start_block must be >= 0, got {n_blocks}, {start_block}")
        L = self.block_len
        rms = np.empty((n_blocks, self.n_channels), dtype=np.float32)
        b = 0
        while b < n_blocks:
            blk = start_block + b
            nb = min(self.chunk_blocks - blk % self.chunk_blocks, n_blocks - b)
            rms[b:b + nb] = self._block_rms(self.counts(blk * L, nb * L)).T
            b += nb
        t0 = self.config.t0_start + (start_block + np.arange(n_blocks, dtype=np.int64)) * L
        return t0, rms

    # -- the byte stream ---------------------------------------------------------------
    def n_blocks_for(self, duration_s: float) -> int:
        """Whole blocks in ``duration_s`` seconds."""
        if not duration_s >= 0:
            raise ValueError(f"duration must be >= 0 s, got {duration_s!r}")
        return int(math.floor(duration_s * self.fs / self.block_len + 1e-9))

    def _status(self, overruns: int, sample_index: int) -> Status:
        cfg = self.config
        return Status(
            fw_version=cfg.fw_version,
            mode=MODE_RMS if cfg.mode == "rms" else MODE_RAW,
            n_channels=self.n_channels, fs=self.fs, block_len=self.block_len,
            tacho_inputs=1 if cfg.tacho else 0, tacho_ppr=cfg.ppr,
            overruns=overruns, uptime_s=(cfg.t0_start + sample_index) // self.fs,
            scale=tuple(float(v) for v in self.scale),
            offset=tuple(float(v) for v in self.offset),
        )

    def iter_blocks(self, n_blocks: int | None = None) -> Iterator[tuple[bytes, int]]:
        """(bytes, number of frames) per block period, for n_blocks (None: forever)."""
        cfg = self.config
        L = self.block_len
        raw = cfg.mode == "raw"
        seq = cfg.seq_start
        overruns = 0
        b = 0
        while n_blocks is None or b < n_blocks:
            nb = self.chunk_blocks - b % self.chunk_blocks
            if n_blocks is not None:
                nb = min(nb, n_blocks - b)
            counts = self.counts(b * L, nb * L)
            clipped = self._block_clipped(counts)  # (C, nb)
            if raw:
                chan_blocks = counts.reshape(self.n_channels, nb, L)
            else:
                rms = self._block_rms(counts).T  # (nb, C)
                any_clip = np.asarray(clipped.any(axis=0))
            if cfg.tacho:
                e_blk, e_off = self.tacho_edges(b, nb)
                bounds = np.searchsorted(e_blk, np.arange(b, b + nb + 1))
            for i in range(nb):
                blk = b + i
                sample = blk * L
                t0 = cfg.t0_start + sample
                parts = []
                if blk % self._status_every == 0:
                    parts.append(encode_status(seq, t0, self._status(overruns, sample)))
                    seq = (seq + 1) & 0xFFFF
                over = FLAG_OVERRUN if blk in self._overrun_set else 0
                if raw:
                    for c in range(self.n_channels):
                        flags = (FLAG_CLIPPED if clipped[c, i] else 0) | (over if c == 0 else 0)
                        parts.append(encode_raw(seq, t0, c, chan_blocks[c, i], flags))
                        seq = (seq + 1) & 0xFFFF
                else:
                    flags = (FLAG_CLIPPED if any_clip[i] else 0) | over
                    parts.append(encode_rms(seq, t0, rms[i], flags))
                    seq = (seq + 1) & 0xFFFF
                if over:
                    overruns += 1
                if cfg.tacho:
                    parts.append(encode_tacho(seq, t0, 0, e_off[bounds[i]:bounds[i + 1]]))
                    seq = (seq + 1) & 0xFFFF
                if blk in self._resent_set:
                    again = parts
                    if cfg.resend_new_seq:
                        again = [_renumbered(p, seq + k) for k, p in enumerate(parts)]
                        seq = (seq + len(parts)) & 0xFFFF
                    parts += again
                yield b"".join(parts), len(parts)
            b += nb

    def iter_block_bytes(self, n_blocks: int | None = None) -> Iterator[bytes]:
        """All bytes the board sends in each block period, for n_blocks (None: forever)."""
        for data, _ in self.iter_blocks(n_blocks):
            yield data

    def generate(self, duration_s: float) -> bytes:
        """All bytes of ``duration_s`` seconds (for small durations; see write_capture)."""
        return b"".join(self.iter_block_bytes(self.n_blocks_for(duration_s)))

    def write_capture(self, path: str | Path, duration_s: float, *, chunk_blocks: int = 1000) -> dict[str, int]:
        """Write ``duration_s`` seconds of bytes to ``path`` as fast as possible.

        Streams in chunks of ``chunk_blocks`` blocks (bounded memory). Returns
        ``{"frames", "bytes", "blocks"}``.
        """
        if chunk_blocks < 1:
            raise ValueError(f"chunk_blocks must be >= 1, got {chunk_blocks}")
        n_blocks = self.n_blocks_for(duration_s)
        frames = total = blocks = 0
        pending: list[bytes] = []
        with open(path, "wb") as f:
            for data, nf in self.iter_blocks(n_blocks):
                pending.append(data)
                frames += nf
                total += len(data)
                blocks += 1
                if len(pending) >= chunk_blocks:
                    f.write(b"".join(pending))
                    pending.clear()
            if pending:
                f.write(b"".join(pending))
        return {"frames": frames, "bytes": total, "blocks": blocks}


# --------------------------------------------------------------------------- link budget

#: the UART's default rate (docs/PROTOCOL.md, Link)
DEFAULT_BAUD = 921600
_BITS_PER_BYTE = 10  # 8N1: start bit, 8 data bits, stop bit
_TACHO_EDGES_BUDGET = 4  # docs/PROTOCOL.md's table: TACHO with <= 4 edges per block


def link_streams(mode: str, n_channels: int, block_len: int = 250, fs: int = 25000,
                 tacho: bool = False, *, tacho_edges: int = _TACHO_EDGES_BUDGET,
                 status_per_s: float = 1.0) -> dict[str, float]:
    """Bytes per second of each stream the board sends (docs/PROTOCOL.md, byte budget table).

    Every frame costs 18 bytes of overhead (sync, header, CRC) plus its payload:
    RMS ``4 C`` per block; RAW ``2 block_len`` per channel and block; TACHO
    ``2 + 4 N`` per block with N = ``tacho_edges``; STATUS ``20 + 8 C`` once a
    second. Returns ``{"rms" or "raw", "tacho" (if wired), "status"}``.
    """
    if mode not in ("rms", "raw"):
        raise ValueError(f"mode must be 'rms' or 'raw', got {mode!r}")
    if not isinstance(n_channels, (int, np.integer)) or not 1 <= n_channels <= 8:
        raise ValueError(f"n_channels must be an integer 1..8, got {n_channels!r}")
    if not block_len >= 1 or not fs > 0:
        raise ValueError(f"block_len and fs must be positive, got {block_len!r}, {fs!r}")
    if not tacho_edges >= 0:
        raise ValueError(f"tacho_edges must be >= 0, got {tacho_edges!r}")
    blocks_per_s = fs / block_len
    ovh = OVERHEAD
    out: dict[str, float] = {}
    if mode == "rms":
        out["rms"] = (ovh + 4 * n_channels) * blocks_per_s
    else:
        out["raw"] = (ovh + 2 * block_len) * n_channels * blocks_per_s
    if tacho:
        out["tacho"] = (ovh + 2 + 4 * tacho_edges) * blocks_per_s
    out["status"] = (ovh + 20 + 8 * n_channels) * status_per_s
    return out


def link_budget(mode: str, n_channels: int, block_len: int, fs: int, tacho: bool, baud: float,
                *, tacho_edges: int = _TACHO_EDGES_BUDGET) -> tuple[float, bool, str]:
    """(bytes_per_s, fits, message): can a UART at ``baud`` (8N1, 10 bits a byte) carry the stream?

    ``bytes_per_s`` is the sum of :func:`link_streams` (data, TACHO with
    ``tacho_edges`` edges per block, STATUS). At 921600 baud (92 160 B/s) one
    RAW channel with a tacho fits (56 % + 4 %); two RAW channels do not.
    ``message`` is one line for a log or a warning.
    """
    if not (baud > 0 and math.isfinite(baud)):
        raise ValueError(f"baud must be a positive number, got {baud!r}")
    streams = link_streams(mode, n_channels, block_len, fs, tacho, tacho_edges=tacho_edges)
    total = float(sum(streams.values()))
    capacity = baud / _BITS_PER_BYTE
    fits = total <= capacity
    what = f"{mode.upper()} {n_channels} ch" + (" + TACHO" if tacho else "") + " + STATUS"
    verdict = "fits" if fits else ("does not fit" + ("; more raw channels need USB CDC" if mode == "raw" else ""))
    msg = (f"{what}: {total:,.0f} B/s = {100 * total / capacity:.0f} % of a {baud:g}-baud UART "
           f"({capacity:,.0f} B/s): {verdict}")
    return total, fits, msg


def _renumbered(frame: bytes, seq: int) -> bytes:
    """``frame`` (a complete one, sync to CRC) under seq ``seq``: its header's seq and its CRC."""
    body = bytearray(frame[2:-4])
    body[2:4] = (seq & 0xFFFF).to_bytes(2, "little")
    return frame[:2] + bytes(body) + zlib.crc32(body).to_bytes(4, "little")
