"""The raw chain of one machine: shaft speed + RAW samples -> orders.

Owns the glue between the :class:`~cmsensord.pipeline.Processor` (which decodes
frames and converts counts to m/s²) and two pieces of pure DSP:

* :class:`cmsensord.dsp.tacho.TachoTracker` turns edge times into speed and
  shaft angle at every sample (pulse repair, least-squares smoothing);
* :class:`cmsensord.dsp.order_tracker.OrderTracker`, the recursive
  angular-velocity Vold-Kalman tracker of seed 001, runs over all channels of
  the machine with the gains shared (they depend only on the speed).

The tracker runs on the tacho's causal speed by default (``orders.speed:
causal``): the speed at a sample comes only from the edges at or before it
(:meth:`TachoTracker.evaluate_causal`), so samples are tracked as soon as the
TACHO frame of their block has arrived, and the result does not depend on how
the stream was cut into reads: live and replay give the same messages.  With
``orders.speed: final`` samples wait until the smoothed speed is final for them
(``final_until``, smoothing_revs + 1..2 pulses later), which is more accurate
at low speed and later.  Output: ``/cm/<channel>/orders`` per output block
(10 Hz by default), order alarms and tacho events.

Missing samples: a lost RAW frame (one channel's block) and a gap in the RAW
stream of at most ``MAX_FILL_S`` reach the tracker as NaN, which it treats as
missing: no measurement update (a time update only) for every tracker sample
the missing input reaches through the anti-alias filter
(:attr:`OrderTracker.missing_window`), see "Missing samples" in
:mod:`cmsensord.dsp.order_tracker`.  The order estimates there are
predictions; each /orders message says which fraction of its block's samples
had no measurement (``missing_fraction``, 0 when none).

Limitations (documented, not hidden):

* A gap longer than ``MAX_FILL_S`` restarts the tracker (its state starts over).
* After a gap the tracker weights new data with its steady-state (tabulated)
  gains, not with the larger gains the grown uncertainty would call for, and the
  smoother uses the steady-state covariance through the gap: the blocks right
  before (smoothed) and after a gap are less accurate than without it, the more
  so the longer the gap and the closer the orders (close_orders, one lost RAW
  frame 13-23 ms after a block at 1100 rpm: that smoothed block 0.2 % -> 4.8 %
  off in order 4; at 2 kHz, r = 50, the first block after a 1-s gap at 900 rpm
  38 % causal; measured in :mod:`cmsensord.dsp.order_tracker`).  Only the
  blocks holding missing samples are flagged.
* A block that had no measurement at all (``missing_fraction`` 1) is a pure
  prediction: it keeps the amplitudes from before the gap.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from cmsensord.config import ChannelConfig, Config
from cmsensord.dsp.order_tracker import OrderAlarm, OrderTracker, TrackedComponent
from cmsensord.dsp.tacho import TachoTracker

#: a gap in the RAW stream up to this long is filled; a longer one restarts the tracker
MAX_FILL_S = 1.0


def _tracked(c, default_pct: float) -> TrackedComponent:
    """A configured component; without its own r or bandwidth it gets orders.bandwidth_pct."""
    own = c.r is not None or c.bandwidth_hz is not None or c.bandwidth_pct is not None
    return TrackedComponent(c.name, order=c.order, freq_hz=c.freq_hz, r=c.r,
                            bandwidth_hz=c.bandwidth_hz,
                            bandwidth_pct=c.bandwidth_pct if own else default_pct)


class OrderChain:
    """Tacho + order tracker for the channels of one machine (see module docstring)."""

    def __init__(self, cfg: Config, channels: tuple[ChannelConfig, ...], tacho: TachoTracker, *,
                 fs: int, write: Callable[[str, str, int, dict], None],
                 event: Callable[..., None], stamp: Callable[[int], int]):
        self.cfg = cfg
        self.channels = channels
        self.fs = fs
        self.write = write
        self.event = event
        self.stamp = stamp
        o = cfg.orders
        self.components = tuple(_tracked(c, o.bandwidth_pct) for c in o.components)
        self.tacho = tacho                      # owned and fed by the Processor
        self.tracker = OrderTracker(self.components, fs_in=fs, max_rpm=o.max_rpm,
                                    n_channels=len(channels), q1=o.q1, min_rpm=o.min_rpm,
                                    smoother_lag_s=o.smoother_lag_s or None,
                                    output_rate_hz=o.output_rate_hz)
        levels = {c.name: c.alarm_rms for c in o.components if c.alarm_rms is not None}
        self.alarm = OrderAlarm(self.components, levels, n_channels=len(channels),
                                hysteresis=1.0 - o.alarm_clear)
        tr = self.tracker
        self.causal = o.speed == "causal"
        if self.causal:     # the speed at a sample comes from the edges up to it: no wait
            self.latency_s = tr.latency_s
            how = "causal speed"
        else:               # the smoothed speed is final h + 1..2 pulses later
            revs = (self.tacho.half_window + 2) / self.tacho.ppr
            at = min(1720.0, o.max_rpm)
            self.latency_s = revs * 60.0 / at + tr.latency_s
            how = f"final speed: tacho {1000 * revs * 60 / at:.0f} ms at {at:.0f} rpm"
        # said with the stamp of the first sample (add_samples): the same however the stream was read
        self._hello = (f"order tracker: {len(self.components)} component(s), decimation "
                       f"{tr.decimate} to {tr.fs_track:g} Hz, {tr.output_rate_hz:g} Hz output; latency "
                       f"{1000 * self.latency_s:.0f} ms ({how}, tracker {1000 * tr.latency_s:.0f} ms)")
        self._parts: list[np.ndarray] = []      # samples waiting for a final speed, (n, C) each
        self._waiting = 0
        self.sample0: int | None = None         # board sample index of the tracker's first input
        self.next_sample: int | None = None     # board sample index of the next input expected
        self.filled_samples = 0                 # samples given to the tracker as missing (NaN in a channel)

    # ---------------------------------------------------------------- input
    def tacho_updated(self) -> None:
        """The tacho has new edges: track the samples whose speed is now final."""
        self._drain(final=False)

    def add_samples(self, start: int, y: np.ndarray) -> None:
        """m/s² samples (n, C) from board sample ``start`` on; NaN where a block was lost."""
        if self.next_sample is None:
            self.sample0 = self.next_sample = start
            self.event("config", None, self._hello, self.stamp(start))
        gap = start - self.next_sample
        if gap < 0 or gap > MAX_FILL_S * self.fs:
            self._drain(final=True)
            self.tracker.reset()
            self.sample0 = self.next_sample = start
            self.event("config", None, f"order tracker restarted: RAW stream jumped by {gap} samples",
                       self.stamp(start))
        elif gap > 0:                           # missing: the tracker does a time update only
            self._parts.append(np.full((gap, len(self.channels)), np.nan))
            self._waiting += gap
            self.filled_samples += gap
        missing = np.isnan(y)
        if missing.any():                       # lost RAW frames: NaN, passed on as missing
            self.filled_samples += int(missing.any(axis=1).sum())
        self._parts.append(y)
        self._waiting += y.shape[0]
        self.next_sample = start + y.shape[0]
        self._drain(final=False)

    def finish(self) -> None:
        """End of the stream: track what waits, with the provisional speed."""
        self._drain(final=True)

    # ---------------------------------------------------------------- tracking
    def _drain(self, final: bool) -> None:
        if not self._waiting:
            return
        first = self.next_sample - self._waiting
        if final:
            upto = self.next_sample
        elif self.causal:
            upto = min(self.next_sample, self.tacho.covered_until)
        else:
            upto = min(self.next_sample, math.floor(self.tacho.final_until))
        n = upto - first
        if n <= 0:
            return
        y = np.concatenate(self._parts) if len(self._parts) > 1 else self._parts[0]
        take, rest = y[:n], y[n:]
        self._parts = [rest] if rest.shape[0] else []
        self._waiting = rest.shape[0]
        if self.causal:
            hz, valid = self.tacho.causal_range(first, upto)
        else:
            hz, _, valid = self.tacho.evaluate(np.arange(first, upto))
        rpm = np.where(valid & np.isfinite(hz), 60.0 * hz, 0.0)
        out = self.tracker.process(take, rpm)
        self._write_blocks(out.blocks, "recursive")
        if out.smoothed_blocks is not None:
            self._write_blocks(out.smoothed_blocks, "smoothed")
        for a in self.alarm.update(out.blocks):
            ch = self.channels[a.channel].name
            stamp = self.stamp(self.sample0 + int(a.block_start) * self.tracker.decimate)
            if a.kind == "onset":
                self.event("order_alarm", ch, f"{ch}: {a.component} RMS {a.rms:.3g} m/s² reached the "
                           f"alarm level {a.level:.3g} at {a.rpm:.0f} rpm", stamp,
                           component=a.component, rpm=round(a.rpm, 1), rms=a.rms)
            else:
                self.event("order_alarm_clear", ch, f"{ch}: {a.component} RMS {a.rms:.3g} m/s² back "
                           f"below {self.cfg.orders.alarm_clear:g} x {a.level:.3g} at {a.rpm:.0f} rpm",
                           stamp, component=a.component, rpm=round(a.rpm, 1), rms=a.rms)

    def _write_blocks(self, blocks, method: str) -> None:
        comps = self.components
        B = self.tracker.block
        for e in range(len(blocks.start)):
            stamp = self.stamp(self.sample0 + int(blocks.t_in[e]))
            rpm = float(blocks.rpm[e])
            ok = bool(blocks.valid[e])
            freqs = [float(c.freq(rpm)) for c in comps]
            for ci, ch in enumerate(self.channels):
                gone = int(blocks.missing[e, ci]) / B
                orders = []
                for k, c in enumerate(comps):
                    rms = float(blocks.rms[e, ci, k])
                    amp = float(blocks.amplitude[e, ci, k])
                    orders.append({"name": c.name, "order": c.order, "freq_hz": freqs[k],
                                   "rms": rms if ok and rms == rms else None,
                                   "amplitude": amp if ok and amp == amp else None})
                self.write(f"/cm/{ch.name}/orders", "orders", stamp, {
                    "channel": ch.name, "speed_rpm": rpm if rpm == rpm else None, "valid": ok,
                    "method": method, "orders": orders, "missing_fraction": gone})
