"""The indicator chain: samples by board time -> one record per channel per interval.

RAW mode (:class:`IndicatorChain`): the m/s² samples of the vibration channels
are gathered into intervals of ``N = round(indicators.interval_s x fs)`` (at most 65536) board
samples, counted from the first sample of the stream, so an interval holds the
same samples however the stream was cut into reads, frames or batches.  A
complete interval waits for its shaft speed (the tacho's causal speed, final
once TACHO frames cover the interval's end; at most ``MAX_WAIT_S``), then
:func:`cmsensord.dsp.indicators.compute` makes its record, one
``/cm/<channel>/indicators`` message per channel, stamped at the interval's end.

* Speed: the mean of the tacho's causal speed at 16 points of the interval (None
  when fewer than half are valid: the machine stopped or the tacho is lost);
  without a tacho, ``indicators.rpm``.  The velocity band (none configured) follows that
  speed, else ``indicators.rpm`` (:meth:`~cmsensord.dsp.indicators.Setup.band_at`).
* An interval with missing samples (lost RAW frames, a gap, the end of the stream)
  gives the waveform statistics of the samples it has, with ``missing_fraction``.  Missing
  at most ``indicators.max_missing_fraction`` of them, it gives the spectral indicators too,
  from the samples it has (:func:`~cmsensord.dsp.indicators.gapped.compute_gapped`: the gaps
  zero, the window's energy over the samples present corrected for); missing more, those
  are listed as unavailable.
* A bearing line that the envelope spectrum's bins (1 / the interval's length) do not resolve
  (:mod:`cmsensord.dsp.indicators.resolution`) is left out and listed as unavailable, as
  ``<bearing>.<line>``; the first record with such a set of lines of a bearing comes after a
  ``lines_unresolved`` event (a warning) naming them, the bin width, the rules on them and the
  record length that resolves them.

RMS mode (:class:`RmsIndicators`): the board's 100 Hz block RMS supports the
overall acceleration RMS only, sqrt(mean(block RMS^2)) over the interval (the
board's RMS keeps any DC offset); every other indicator is listed unavailable.  An
interval is a whole number of blocks, ``indicators.interval_s`` rounded to the nearest
(half to even), at least one (:func:`~cmsensord.monitor.record_length.rms_blocks`).

:class:`Indicators` is what the Processor holds: it makes the chains for the
vibration channels (again when the rate or the channels change, the old one
finished), and keeps their records until :meth:`Indicators.take` asks for those
stamped up to a decision's stamp, so the order of all messages does not depend
on how the stream was read.  An interval's stamp is its end, taken when it
closes; a new time segment (a board reset) finishes the open intervals first.  A step of
the wall clock (:meth:`~cmsensord.monitor.clock.BlockClock.restep`) moves the stamps of the
records not written yet, and the newest of each topic, by its shift, so each topic goes on
in time order on the new time base, back or forward.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from cmsensord.config import ChannelConfig, Config
from cmsensord.dsp.indicators import Band, Bearing, IndicatorRecord, Setup, compute_many
from cmsensord.dsp.indicators.bearings import Geometry
from cmsensord.dsp.indicators.envelope import envelope_band
from cmsensord.dsp.indicators.gapped import compute_gapped
from cmsensord.dsp.indicators.statistics import waveform_stats
from cmsensord.monitor import messages
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.empty_bands import empty_band_events, empty_bands
from cmsensord.monitor.events import Event
from cmsensord.monitor.line_notes import line_notes
from cmsensord.monitor.record_length import MAX_INTERVAL_SAMPLES, rms_blocks
from cmsensord.sinks.schemas import indicators_topic

if TYPE_CHECKING:
    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.monitor.raw import RawBlocks

#: a complete interval waits at most this long (board time) for the tacho to cover it
MAX_WAIT_S = 10.0
#: points of the interval at which the tacho speed is read
SPEED_POINTS = 16
#: RMS mode: whole intervals of back-to-back blocks from which they are summed in one pass
#: (:meth:`RmsIndicators._whole`; the same sums as block by block)
ONE_PASS_INTERVALS = 1
#: every indicator a RAW record can carry, for ``unavailable``
SPECTRAL = ("velocity_rms_mm_s", "zone", "envelope_rms", "bearings", "bands")
WAVEFORM = ("accel_peak", "crest_factor", "kurtosis")


def channel_setup(cfg: Config, ch: ChannelConfig, fs: float) -> Setup:
    """The :class:`~cmsensord.dsp.indicators.Setup` of one channel from the configuration."""
    ic = cfg.indicators
    vb = ic.velocity_band_hz
    bands = tuple(Band(b.name, b.lo_hz, b.hi_hz) if b.lo_hz is not None and b.hi_hz is not None
                  else Band(b.name, b.lo_order or 0.0, b.hi_order or 0.0, orders=True) for b in ic.bands)
    bearings = tuple(Bearing(b.name, Geometry(b.elements, b.ball_diameter, b.pitch_diameter, b.contact_angle_deg))
                     for b in cfg.bearings if b.channel == ch.name)
    return Setup(fs, (vb[0], vb[1]) if vb else None,
                 envelope_band(fs, ic.envelope_band_hz), ic.machine_group, ic.foundation,
                 ic.velocity_baseline_mm_s, ic.slip_pct / 100.0, bearings, bands, ic.rpm)


def _num(x: float) -> float:
    return round(float(x), 9)


def above_nyquist(cfg: Config, fs: float) -> list[tuple[str, tuple[float, float], tuple[str, ...]]]:
    """The configured bands in Hz that start at or above fs/2, where a board sampling at ``fs``
    has no content: (key, [lo, hi] Hz, the values they make unavailable).  Their values would
    read 0 (zone A), so a record lists them unavailable instead."""
    ic, half = cfg.indicators, fs / 2.0
    out: list[tuple[str, tuple[float, float], tuple[str, ...]]] = []
    for key, band, names in (("indicators.velocity_band_hz", ic.velocity_band_hz, ("velocity_rms_mm_s", "zone")),
                             ("indicators.envelope_band_hz", ic.envelope_band_hz, ("envelope_rms", "bearings"))):
        if band and band[0] >= half:
            out.append((key, (float(band[0]), float(band[1])), names))
    for i, b in enumerate(ic.bands):
        if b.lo_hz is not None and b.hi_hz is not None and b.lo_hz >= half:
            out.append((f"indicators.bands[{i}]", (float(b.lo_hz), float(b.hi_hz)), (f"band.{b.name}",)))
    return out


def nyquist_event(dead: list[tuple[str, tuple[float, float], tuple[str, ...]]], fs: float, stamp: int) -> Event:
    """The warning that ``dead`` (:func:`above_nyquist`) bands lie past the board's Nyquist frequency."""
    what = "; ".join(f"{key} {lo:g}-{hi:g} Hz" for key, (lo, hi), _ in dead)
    names = ", ".join(n for _, _, ns in dead for n in ns)
    return Event("band_above_nyquist", None, f"{what}: at or above the Nyquist frequency {fs / 2:g} Hz of the board's "
                 f"{fs:g} Hz sampling, no signal there: {names} listed unavailable in the indicator records; "
                 "set a band below it", stamp)


def without_dead(fields: dict, dead: list[tuple[str, tuple[float, float], tuple[str, ...]]]) -> dict:
    """A record's ``fields`` with the values of the ``dead`` bands left out and listed unavailable."""
    names = [n for _, _, ns in dead for n in ns]
    drop = set(names) | ({"velocity_alarm_mm_s"} if "zone" in names else set())
    out = {k: v for k, v in fields.items() if k not in drop}
    out["bands"] = [b for b in fields.get("bands", ()) if f"band.{b['name']}" not in drop]
    out["unavailable"] = list(dict.fromkeys([*fields.get("unavailable", ()), *names]))
    return out


def record_fields(r: IndicatorRecord) -> dict:
    """The message fields of a RAW record (absent: not computed)."""
    out: dict = {}
    for k, v in (("accel_rms", r.accel.rms), ("accel_peak", r.accel.peak),
                 ("crest_factor", r.accel.crest_factor), ("kurtosis", r.accel.kurtosis),
                 ("velocity_rms_mm_s", r.velocity_rms_mm_s), ("envelope_rms", r.envelope_rms)):
        if v == v:
            out[k] = _num(v)
    out.update(velocity_band_hz=list(r.velocity_band), zone=r.zone,
               zone_boundaries_mm_s=list(r.zone_boundaries_mm_s), envelope_band_hz=list(r.envelope_band))
    if r.velocity_alarm_mm_s is not None:
        out["velocity_alarm_mm_s"] = _num(r.velocity_alarm_mm_s)
    out["bearings"] = [_bearing(b) for b in r.bearings]
    out["bands"] = [{"name": band.name, "lo_hz": _num(lo), "hi_hz": _num(hi), "rms": _num(rms)}
                    for band, (lo, hi), rms in r.bands]
    unresolved = [f"{b.name}.{k}" for b in r.bearings for k in b.unresolved + b.beyond]
    if unresolved:
        out["unavailable"] = unresolved
    return out


def _bearing(b) -> dict:
    d: dict = {"name": b.name}
    if b.freqs is not None:
        d.update({f"{k}_hz": _num(v) for k, v in b.freqs._asdict().items()})
    d["lines"] = {k: {"amplitude": _num(p.amplitude), "freq_hz": _num(p.freq_hz),
                      **({"ratio": _num(p.ratio)} if p.ratio == p.ratio else {})}
                  for k, p in b.lines.items()}
    return d


class IndicatorChain:
    """RAW samples of ``channels`` -> /cm/<channel>/indicators (see module docstring).

    ``tacho``: returns the tacho tracker, or None when the board has no tacho; ``uncovered``: which
    board samples no TACHO frame covers (:meth:`~cmsensord.monitor.shaft.Shaft.uncovered`;
    default: those after the newest)."""

    def __init__(self, cfg: Config, channels: tuple[ChannelConfig, ...], *, fs: int, clock: BlockClock,
                 tacho: Callable[[], TachoTracker | None],
                 uncovered: Callable[[np.ndarray], np.ndarray] | None = None, told: set | None = None):
        self.cfg, self.channels, self.fs, self.clock, self.tacho = cfg, channels, fs, clock, tacho
        #: the unresolved bearing lines said already (:func:`~.line_notes.line_notes`)
        self.told: set = set() if told is None else told
        self.uncovered = uncovered or self._after_newest
        self.N = max(2, min(MAX_INTERVAL_SAMPLES, round(cfg.indicators.interval_s * fs)))
        self.index = [ch.index for ch in channels]
        self.setups = [channel_setup(cfg, ch, fs) for ch in channels]
        #: the configured bands past fs/2 (:func:`above_nyquist`)
        self.dead = above_nyquist(cfg, fs)
        self.buf = np.full((self.N, len(channels)), np.nan)
        self._dirty = False                     # samples written to buf since it was last NaN
        self.start: int | None = None          # board sample of the open interval's first sample
        # (start, samples, stamp, their finite mask or None: all finite) waiting for a speed
        self.pending: list[tuple[int, np.ndarray, int, np.ndarray | None]] = []
        self.newest = 0                        # board sample after the newest one given

    # ---------------------------------------------------------------- input
    def add_samples(self, start: int, y: np.ndarray) -> list:
        """m/s² samples (n, C) from board sample ``start`` on; NaN where lost.  The rows of a
        whole interval in ``y`` wait as they are (not copied): ``y`` is not to be written after."""
        pos = start
        while len(y):
            if self.start is None or pos < self.start:          # the first, or the clock stepped back
                self._close()
                self.start = self.newest = pos
            elif pos >= self.start + self.N:                    # a gap past the open interval
                self._close()
                self.start += (pos - self.start) // self.N * self.N
            off = pos - self.start
            take = min(self.N - off, len(y))
            if take == self.N:                  # a whole interval in y: it waits as it is
                self._close(np.ascontiguousarray(y[:take], dtype=np.float64))
            else:
                self.buf[off:off + take] = y[:take]
                self._dirty = True
                if off + take == self.N:
                    self._close()
            pos += take
            y = y[take:]
        self.newest = max(self.newest, pos)
        return self.release()

    def _close(self, whole: np.ndarray | None = None) -> None:
        """The open interval is done: to the waiting list if it has any sample, with the stamp
        of its end taken now, in the time segment its samples came in.  ``whole``: all its
        samples, given at once (they wait as given, not copied: the caller's array is not
        written again); else those gathered in the buffer."""
        x = self.buf if whole is None else whole
        if self.start is not None:
            finite = np.isfinite(x)
            full = bool(finite.all())
            if full or finite.any():
                self.pending.append((self.start, x.copy() if whole is None else x,
                                     self.clock.stamp_ns(self.start + self.N), None if full else finite))
        if self.start is not None:
            self.start += self.N
        if self._dirty:
            self.buf[:] = np.nan
            self._dirty = False

    def close_open(self) -> list:
        """The open interval (partial) closed, if it has a sample, and every waiting one."""
        if self.start is not None and np.isfinite(self.buf).any():
            self._close()
        return self.release(final=True)

    def finish(self) -> list:
        """End of the stream or of a time segment: the open interval (partial) and every waiting
        one; the next samples start a new interval."""
        self._close()
        self.start = None
        return self.release(final=True)

    # ---------------------------------------------------------------- output
    def release(self, *, final: bool = False, bounded: bool = True) -> list:
        """Records of the waiting intervals whose speed is known (all with ``final``; with
        ``bounded``, also those waiting longer than MAX_WAIT_S)."""
        ready = []
        tacho = self.tacho()
        while self.pending:
            s = self.pending[0][0]
            end = s + self.N
            late = bounded and self.newest - end > MAX_WAIT_S * self.fs
            if tacho is not None and tacho.covered_until < end and not (final or late):
                break
            ready.append(self.pending.pop(0))
        return self._records(ready, tacho) if ready else []

    def _after_newest(self, samples: np.ndarray) -> np.ndarray:
        """The samples after the newest TACHO frame (``uncovered`` when none is given)."""
        tacho = self.tacho()
        return samples >= (tacho.covered_until if tacho is not None else 0)

    def _speeds(self, ready: list[tuple[int, np.ndarray, int, np.ndarray | None]],
                tacho: TachoTracker | None) -> list[tuple[float | None, str | None]]:
        """(shaft speed [Hz] or None, its source) of the intervals ``ready`` (start, samples,
        stamp, finite mask or None): the mean of the tacho's causal speed at those of its
        SPEED_POINTS points at a sample it holds (over lost frames the tacho's speed is an
        extrapolation; None when fewer than half of them are valid, a point no TACHO frame covers
        being not valid: an interval let go after the longest wait, or in a silence of the tacho,
        has no speed there), all read in one call; without a tacho, ``indicators.rpm``."""
        if tacho is None:
            rpm = self.cfg.indicators.rpm
            return [(rpm / 60.0, "config") if rpm else (None, None)] * len(ready)
        at = (np.arange(SPEED_POINTS) + 0.5) * self.N / SPEED_POINTS
        points = np.array([r[0] for r in ready])[:, None] + at[None, :]
        hz, ok = tacho.evaluate_causal(points)
        ok &= ~self.uncovered(points.ravel()).reshape(points.shape)
        seen = np.ones_like(ok)
        for k, (_, _, _, finite) in enumerate(ready):
            if finite is not None:
                seen[k] = _seen_at(finite, at.astype(np.int64))
        ok &= seen
        return [(None, None) if not o.any() or o.sum() < 0.5 * n else (float(np.mean(h[o])), "tacho")
                for h, o, n in zip(hz, ok, seen.sum(axis=1))]

    def _records(self, ready: list[tuple[int, np.ndarray, int, np.ndarray | None]],
                 tacho: TachoTracker | None) -> list:
        """The messages of the intervals ``ready`` (start, samples, stamp, finite mask or None),
        in order, channel by channel; the complete records' indicators computed together
        (:func:`compute_many`: the numbers of one :func:`compute` per record); before a record, the
        ``lines_unresolved`` events of its bearing lines not said yet (:func:`~.line_notes.line_notes`)."""
        rows: list = []                 # (stamp, channel, head, missing, fields, a record or None: computed)
        todo: list = []                 # (x, setup, shaft_hz) of the complete records
        for (_, x, stamp, finite), (shaft_hz, source) in zip(ready, self._speeds(ready, tacho)):
            head = {"mode": "raw", "interval_s": self.N / self.fs}
            if shaft_hz is not None:
                head.update(speed_rpm=_num(60.0 * shaft_hz), speed_source=source)
            # the channels with every sample (a mask kept only when a sample is missing)
            whole = [True] * len(self.channels) if finite is None else np.logical_and.reduce(finite, axis=0).tolist()
            for c, ch in enumerate(self.channels):
                xc = x[:, c]
                if whole[c]:
                    todo.append((xc, self.setups[c], shaft_hz))
                    rows.append((stamp, ch.name, head, 0.0, None, self.setups[c], shaft_hz))
                    continue
                assert finite is not None
                ok = finite[:, c]
                if not ok.any():
                    continue
                missing = float(np.count_nonzero(~ok)) / ok.size     # exact at the limit (1 - 0.95 > 0.05)
                if missing <= self.cfg.indicators.max_missing_fraction and ok.sum() >= 2:
                    rows.append((stamp, ch.name, head, missing, compute_gapped(xc, ok, self.setups[c], shaft_hz),
                                 self.setups[c], shaft_hz))
                    continue
                st = waveform_stats(xc)
                fields: dict = {k: _num(v) for k, v in zip(("accel_rms",) + WAVEFORM, st) if v == v}
                fields["unavailable"] = list(SPECTRAL)
                rows.append((stamp, ch.name, head, missing, fields, self.setups[c], shaft_hz))
        records = iter(compute_many(todo))
        out = []
        for stamp, name, head, missing, fields, setup, shaft_hz in rows:
            if not isinstance(fields, dict):        # computed: by compute_many (None) or gapped
                r = next(records) if fields is None else fields
                fields = record_fields(r)
                if shaft_hz is None and (setup.bearings or any(b.orders for b in setup.bands)):
                    fields["unavailable"] = ["speed"] + fields.get("unavailable", [])
                out += line_notes(self.cfg, name, r, setup, self.fs / self.N, stamp, self.told,
                                  MAX_INTERVAL_SAMPLES / setup.fs)
                empty = empty_bands(r, setup)
                if empty:
                    fields = without_dead(fields, empty)
                    out += empty_band_events(name, empty, self.N / self.fs, self.fs, stamp, self.told)
                if self.dead:
                    fields = without_dead(fields, self.dead)
                    if ("nyquist", self.fs) not in self.told:
                        self.told.add(("nyquist", self.fs))
                        out.append(nyquist_event(self.dead, self.fs, stamp))
            out.append(messages.indicators(stamp, name, {**head, "missing_fraction": _num(missing), **fields}))
        return out


class RmsIndicators:
    """RMS mode: the overall acceleration RMS per interval from the board's block RMS."""

    UNAVAILABLE = list(WAVEFORM + SPECTRAL)

    def __init__(self, cfg: Config, channels: tuple[ChannelConfig, ...], *, fs: int, block_len: int,
                 clock: BlockClock):
        self.channels, self.clock, self.fs, self.L = channels, clock, fs, block_len
        self.per = rms_blocks(cfg.indicators.interval_s, fs, block_len)   # blocks per interval
        self.N = self.per * block_len
        self.start: int | None = None
        self.newest: int | None = None          # t0 of the newest block taken
        self.sq = np.zeros(len(channels))
        self.n = np.zeros(len(channels), dtype=np.int64)

    def add(self, t0: np.ndarray, vals: np.ndarray) -> list:
        """Block RMS (B, C_board) of the blocks starting at board samples t0.

        Block by block, an interval opens at a block before its start or past its end and
        closes after a block reaching its end; the blocks of one interval are summed in one
        pass, a running sum in block order (the same sums as one block at a time).  A block
        under the t0 of the block before it (the board's t0 stuck, a block sent again) is
        left out: it would count one place on the board's time grid twice."""
        t0 = np.asarray(t0, dtype=np.int64)
        if len(t0) and (t0[0] == self.newest or (t0[1:] == t0[:-1]).any()):
            keep = t0 != np.concatenate(([self.newest if self.newest is not None else t0[0] - 1], t0[:-1]))
            t0, vals = t0[keep], vals[keep]
        if not len(t0):
            return []
        self.newest = int(t0[-1])
        out: list = []
        idx = [ch.index for ch in self.channels]
        v = np.full((len(t0), len(idx)), np.nan)
        have = [i for i, j in enumerate(idx) if j < vals.shape[1]]
        v[:, have] = vals[:, [idx[i] for i in have]]
        ok = np.isfinite(v)
        sq = np.where(ok, v, 0.0) ** 2
        t = np.asarray(t0, dtype=np.int64)
        B, N, L, per = len(t), self.N, self.L, self.per
        steps = (np.diff(t) != L).nonzero()[0]     # block i to i + 1 is not the next block
        k = 0
        while k < B:
            tk = int(t[k])
            if self.start is None or tk < self.start:
                out += self._close()
                self.start = tk
            elif tk >= self.start + N:
                out += self._close()
                self.start += (tk - self.start) // N * N
            if tk == self.start and not self.n.any():   # whole intervals of back-to-back blocks
                i = int(steps.searchsorted(k))
                K = ((int(steps[i]) + 1 if i < len(steps) else B) - k) // per
                if K >= ONE_PASS_INTERVALS:
                    out += self._whole(sq[k:k + K * per], ok[k:k + K * per], K)
                    k += K * per
                    continue
            end = self.start + N
            # the blocks after k in this interval, up to the first one reaching its end
            nxt = t[k + 1:]
            leave = ((nxt < self.start) | (nxt >= end)).nonzero()[0]
            e = k + 1 + int(leave[0]) if leave.size else B
            close = (t[k:e] + L >= end).nonzero()[0]
            if close.size:
                e = k + int(close[0]) + 1
            self.sq = np.add.accumulate(np.vstack((self.sq[None, :], sq[k:e])), axis=0)[-1]
            self.n += ok[k:e].sum(axis=0)
            if close.size:
                out += self._close()
            k = e
        return out

    def _whole(self, sq: np.ndarray, ok: np.ndarray, K: int) -> list:
        """The records of K whole intervals from the empty one at ``start`` on, of their
        blocks' squares ``sq`` and finite flags ``ok`` (K per, C): what K times the blocks of
        one interval summed in block order and :meth:`_close` give, value for value."""
        C = len(self.channels)
        total = np.add.accumulate(sq.reshape(K, self.per, C), axis=1)[:, -1]   # in block order
        n = ok.reshape(K, self.per, C).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.sqrt(total / n).tolist()
        missing = (1.0 - n / self.per).tolist()
        have = (n > 0).tolist()
        names = [ch.name for ch in self.channels]
        topics = [indicators_topic(name) for name in names]
        interval_s, unavailable, Message = self.N / self.fs, self.UNAVAILABLE, messages.Message
        out = []
        assert self.start is not None
        for j in range(K):
            self.start += self.N
            stamp = self.clock.stamp_ns(self.start)
            out += [Message(topics[c], "indicators", stamp, {   # what messages.indicators makes
                "channel": names[c], "mode": "rms", "interval_s": interval_s,
                "missing_fraction": round(missing[j][c], 9), "accel_rms": round(rms[j][c], 9),
                "unavailable": unavailable}) for c in range(C) if have[j][c]]
        return out

    def close_open(self) -> list:
        """The open interval (partial), if it has a block."""
        return self._close() if self.n.any() else []

    def finish(self) -> list:
        """End of the stream or of a time segment: the open interval; the next block starts anew."""
        out = self._close()
        self.start = self.newest = None
        return out

    def _close(self) -> list:
        out = []
        if self.start is not None:
            stamp = self.clock.stamp_ns(self.start + self.N)
            for c, ch in enumerate(self.channels):
                if self.n[c]:
                    out.append(messages.indicators(stamp, ch.name, {
                        "mode": "rms", "interval_s": self.N / self.fs,
                        "missing_fraction": _num(1.0 - self.n[c] / self.per),
                        "accel_rms": _num(np.sqrt(self.sq[c] / self.n[c])), "unavailable": self.UNAVAILABLE}))
            self.start += self.N
        self.sq[:] = 0.0
        self.n[:] = 0
        return out


class Indicators:
    """The indicator chains of one Processor and their records waiting to be written (see
    module docstring).  ``tacho``: the tacho tracker, or None while there is none; ``uncovered``:
    as :class:`IndicatorChain`'s."""

    def __init__(self, cfg: Config, clock: BlockClock, tacho: Callable[[], TachoTracker | None],
                 uncovered: Callable[[np.ndarray], np.ndarray] | None = None):
        self.cfg, self.clock, self.tacho, self.uncovered = cfg, clock, tacho, uncovered
        self.raw_chain: IndicatorChain | None = None
        self.rms_chain: RmsIndicators | None = None
        #: the records waiting, and before a record the ``lines_unresolved`` events of its lines
        self.records: list[messages.Message | Event] = []
        self._newest: dict[str, int] = {}      # per topic, the stamp of the newest record taken
        self._told: set = set()                # the unresolved bearing lines said (over the chains)
        clock.steps.append(self.restepped)

    def restepped(self, shift_ns: int) -> None:
        """The wall clock stepped: the stamps held (records waiting, intervals waiting for a speed,
        each topic's newest) move by ``shift_ns``, as the time base did."""
        self.records = [dataclasses.replace(m, stamp_ns=(m.stamp_ns or 0) + shift_ns) if isinstance(m, Event)
                        else m._replace(stamp_ns=m.stamp_ns + shift_ns) for m in self.records]
        self._newest = {topic: at + shift_ns for topic, at in self._newest.items()}
        if self.raw_chain is not None:
            self.raw_chain.pending = [(s, x, at + shift_ns, ok) for s, x, at, ok in self.raw_chain.pending]

    def _vibration(self, channels: tuple[ChannelConfig, ...]) -> tuple[ChannelConfig, ...]:
        return tuple(ch for ch in channels if ch.kind != "microphone") if self.cfg.indicators.enabled else ()

    def raw(self, channels: tuple[ChannelConfig, ...], blocks: RawBlocks) -> None:
        """Converted RAW blocks -> the RAW chain of the vibration channels among ``channels``."""
        vib = self._vibration(channels)
        if not vib:
            return
        ind = self.raw_chain
        if ind is None or ind.fs != self.clock.fs or ind.channels != vib:
            if ind is not None:
                self.records += ind.finish()
            ind = self.raw_chain = IndicatorChain(self.cfg, vib, fs=self.clock.fs, clock=self.clock,
                                                  tacho=self.tacho, uncovered=self.uncovered, told=self._told)
        y = blocks.samples(ind.index)
        for a, b in blocks.runs():          # consecutive except across lost blocks
            self.records += ind.add_samples(int(blocks.t0[a]), y[a:b].reshape(-1, len(ind.index)))

    def rms(self, channels: tuple[ChannelConfig, ...], t0: np.ndarray, vals: np.ndarray) -> None:
        """Block RMS (B, C_board) of the blocks at t0 -> the RMS chain."""
        vib = self._vibration(channels)
        if not vib:
            return
        ind = self.rms_chain
        if ind is None or (ind.fs, ind.L) != (self.clock.fs, self.clock.block_len) or ind.channels != vib:
            if ind is not None:
                self.records += ind.finish()
            ind = self.rms_chain = RmsIndicators(self.cfg, vib, fs=self.clock.fs,
                                                 block_len=self.clock.block_len, clock=self.clock)
        self.records += ind.add(t0, vals)

    def release(self) -> None:
        """After a tacho feed: the intervals it covers."""
        if self.raw_chain is not None:
            self.records += self.raw_chain.release()

    def quiet(self) -> None:
        """The link went quiet: the open intervals go out as they are (partial, with their
        ``missing_fraction``) and every waiting one with the speed as known.  The grid of
        intervals stays, so samples after a gap (the frames the board could not send) fall
        in the intervals a replay puts them in.  Only a board that resumes with no frame
        lost (its bytes were late, not lost) gives records a replay would not: the interval
        it was in, closed here, and a new grid from its next sample on."""
        if self.raw_chain is not None:
            self.records += self.raw_chain.close_open()
        if self.rms_chain is not None:
            self.records += self.rms_chain.close_open()

    def finish(self) -> None:
        """End of the stream or of a time segment: every open and waiting interval."""
        for chain in (self.raw_chain, self.rms_chain):
            if chain is not None:
                self.records += chain.finish()

    def take(self, upto_ns: int | None) -> list[messages.Message | Event]:
        """The records stamped at or before ``upto_ns`` (all with None), oldest first, each
        after the events made with it."""
        n = len(self.records) if upto_ns is None else \
            next((i for i, m in enumerate(self.records) if (m.stamp_ns or 0) > upto_ns), len(self.records))
        out, self.records = self.records[:n], self.records[n:]
        for i, m in enumerate(out):             # a re-anchored clock, or a switch of chain,
            if isinstance(m, Event):            # (a lines_unresolved event: stamped, no topic)
                continue
            at = max(m.stamp_ns, self._newest.get(m.topic, 0))   # never steps a topic back
            self._newest[m.topic] = at
            if at != m.stamp_ns:
                out[i] = m._replace(stamp_ns=at)
        return out


def _seen_at(finite: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Whether any channel holds the samples ``idx`` of an interval (``finite``: (N, C) or (N,))."""
    got = finite[idx]
    return got.any(axis=1) if got.ndim == 2 else got
