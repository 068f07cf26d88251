"""The raw chain of one machine: shaft speed + RAW samples -> orders.

Owns the glue between the monitoring chain (which decodes frames and converts
counts to m/s², :mod:`cmsensord.monitor.raw`) and two pieces of pure DSP:

* :class:`cmsensord.dsp.tacho.TachoTracker` turns edge times into speed and
  shaft angle at every sample (pulse repair, least-squares smoothing);
* :class:`cmsensord.dsp.order_tracker.OrderTracker`, the recursive
  angular-velocity Vold-Kalman tracker of Yeh, Pan & Le, runs over all channels of
  the machine with the gains shared (they depend only on the speed).

The tracker runs on the tacho's causal speed by default (``orders.speed:
causal``): the speed at a sample comes only from the edges at or before it
(:meth:`TachoTracker.evaluate_causal`), so samples are tracked as soon as the
TACHO frame of their block has arrived, and the result does not depend on how
the stream was cut into reads: live and replay give the same messages.  With
``orders.speed: final`` samples wait until the smoothed speed is final for them
(``final_until``, smoothing_revs + 1..2 pulses later), which is more accurate
at low speed and later.  Samples wait in a bounded
:class:`~cmsensord.monitor.speed_gate.SpeedGate`: at most ``MAX_WAIT_S``, so a
tacho whose TACHO frames never come cannot make the chain grow without limit.
Output, returned in order to the caller as :class:`~cmsensord.monitor.messages.Message`
and :class:`~cmsensord.monitor.events.Event` items: ``/cm/<channel>/orders`` per
output block (10 Hz by default).  The order alarms (``alarm_rms``) are the alarm manager's
(:mod:`cmsensord.monitor.alarms` reads these messages): delays, latching, suppression.

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
from collections.abc import Callable
from itertools import chain
from math import isfinite

import numpy as np

from cmsensord.config import ChannelConfig, Config
from cmsensord.dsp.order_tracker import OrderTracker, TrackedComponent
from cmsensord.dsp.tacho import TachoTracker
from cmsensord.monitor import messages
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import Event
from cmsensord.monitor.speed_gate import SpeedGate
from cmsensord.sinks.encoded import EncodedMessage
from cmsensord.sinks.orders_encoding import OrdersTemplate
from cmsensord.sinks.schemas import orders_topic

#: a gap in the RAW stream up to this long is filled; a longer one restarts the tracker
MAX_FILL_S = 1.0
#: samples wait at most this long for a final speed (then go with the speed as it is)
MAX_WAIT_S = 10.0
#: /orders messages carry their JSON text, made from the arrays (:meth:`OrderChain._texts`, the
#: plain encoder's bytes); False: plain dicts, encoded by the sink (the reference of the tests)
PRE_ENCODED = True

Out = list  # of messages.Message and Event, in the order they happened


def _tracked(c, default_pct: float) -> TrackedComponent:
    """A configured component; without its own r or bandwidth it gets orders.bandwidth_pct."""
    own = c.r is not None or c.bandwidth_hz is not None or c.bandwidth_pct is not None
    return TrackedComponent(c.name, order=c.order, freq_hz=c.freq_hz, r=c.r,
                            bandwidth_hz=c.bandwidth_hz,
                            bandwidth_pct=c.bandwidth_pct if own else default_pct)


class OrderChain:
    """Tacho + order tracker for the channels of one machine (see module docstring).

    ``tacho`` is fed by its owner; after each feed :meth:`release` tracks what it made final.
    ``clock`` gives the stamps of board sample indices.
    """

    def __init__(self, cfg: Config, channels: tuple[ChannelConfig, ...], tacho: TachoTracker, *,
                 fs: int, clock: BlockClock, uncovered: Callable[[np.ndarray], np.ndarray] | None = None):
        self.cfg = cfg
        self.uncovered = uncovered or (lambda samples: samples >= tacho.covered_until)
        self.channels = channels
        self.fs = fs
        self.clock = clock
        o = cfg.orders
        self.components = tuple(_tracked(c, o.bandwidth_pct) for c in o.components)
        self._by_order = np.array([c.order is not None for c in self.components])
        self._orders = np.array([c.order or 0.0 for c in self.components], dtype=np.float64)
        self._fixed_hz = np.array([c.freq_hz or 0.0 for c in self.components], dtype=np.float64)
        # per component (order, 0.0) or (None, fixed frequency), as Python floats
        self._freq_spec = [(None if c.order is None else float(c.order), float(c.freq_hz or 0.0))
                           for c in self.components]
        self.tacho = tacho
        self.tracker = OrderTracker(self.components, fs_in=fs, max_rpm=o.max_rpm,
                                    n_channels=len(channels), q1=o.q1, min_rpm=o.min_rpm,
                                    smoother_lag_s=o.smoother_lag_s or None,
                                    output_rate_hz=o.output_rate_hz)
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
        self.gate = SpeedGate(round(MAX_WAIT_S * fs))   # samples (n, C) waiting for a final speed
        self.sample0: int | None = None         # board sample index of the tracker's first input
        self._templates: dict[tuple[int, str], str | None] = {}   # (channel, method) -> template
        self._channels: dict[str, list[tuple[str, str, str | None]]] = {}   # method -> _channels_of

    def _event(self, kind: str, channel: str | None, message: str, sample: int, **fields) -> Event:
        return Event(kind, channel, message, self.clock.stamp_ns(sample), fields)

    # ---------------------------------------------------------------- input
    def begin(self, start: int) -> Out:
        """The tracker's first input is board sample ``start``: its config event, stamped there
        (the owner says it before the decisions of the blocks from there, so where it lands among
        the events does not depend on how the stream was read)."""
        self.sample0 = start
        self.gate.restart(start)
        return [self._event("config", None, self._hello, start)]

    def add_samples(self, start: int, y: np.ndarray) -> Out:
        """m/s² samples (n, C) from board sample ``start`` on; NaN where a block was lost.  A ``start``
        less than a block off the end of the samples before (a RAW frame's t0 a few samples off,
        docs/PROTOCOL.md: the frames of a block share it) is taken as following on from them."""
        out: Out = [] if self.sample0 is not None else self.begin(start)
        end = self.gate.end
        assert end is not None                  # restarted above or before
        gap = start - end
        if abs(gap) < self.clock.block_len:     # a t0 a few samples off (no reset either): they follow on
            gap = 0
        if gap < 0 or gap > MAX_FILL_S * self.fs:
            out += self.release(final=True)
            self.tracker.reset()
            self.sample0 = start
            self.gate.restart(start)
            out.append(self._event("config", None, f"order tracker restarted: RAW stream jumped by "
                                   f"{gap} samples", start))
        elif gap > 0:                           # missing: the tracker does a time update only
            self.gate.push(np.full((gap, len(self.channels)), np.nan))
        self.gate.push(y)                       # NaN of lost RAW frames: passed on as missing
        return out + self.release()

    def next_output_sample(self) -> int | None:
        """Board sample index whose arrival completes the next /orders block (None before
        the first samples)."""
        if self.sample0 is None:
            return None
        return self.sample0 + self.tracker.next_block_input()

    def finish(self) -> Out:
        """End of the stream: track what waits, with the provisional speed."""
        return self.release(final=True)

    # ---------------------------------------------------------------- tracking
    def release(self, *, final: bool = False, bounded: bool = False) -> Out:
        """Track the samples whose speed is final (all if ``final``; with ``bounded``, at least
        those waiting longer than MAX_WAIT_S)."""
        if not self.gate.waiting:
            return []
        if final:
            upto = self.gate.first + self.gate.waiting      # the gate's end: everything
        elif self.causal:
            upto = self.tacho.covered_until
        else:
            upto = math.floor(self.tacho.final_until)
        got = self.gate.release(upto, final=final, bounded=bounded)
        if got is None:
            return []
        first, (take,) = got
        blocks, smoothed = self.tracker.process_blocks(take, lambda i: self._rpm(first + i))
        out: Out = self._blocks(blocks, "recursive")
        if smoothed is not None:
            out += self._blocks(smoothed, "smoothed")
        return out

    def _rpm(self, samples: np.ndarray) -> np.ndarray:
        """The speed [rpm] the tracker runs on at board samples (ascending): the tacho's causal
        speed (:meth:`TachoTracker.causal_rpm`), or its final one (``orders.speed``); 0 where
        it is not valid or no TACHO frame covers it (``uncovered``: after the newest, samples let
        go after the longest wait; in a silence between two, :meth:`Shaft.uncovered`).  The
        tracker asks only for the samples it reads (one in its decimation, in the call they
        come in), each the value it has at every sample (:meth:`TachoTracker.causal_range`)."""
        if self.causal:
            rpm = self.tacho.causal_rpm(0, samples)
        else:
            hz, _, valid = self.tacho.evaluate(samples)
            rpm = np.where(valid & np.isfinite(hz), 60.0 * hz, 0.0)
        if len(samples):
            rpm[self.uncovered(samples)] = 0.0
        return rpm

    def _blocks(self, blocks, method: str) -> Out:
        """The /orders messages of tracker blocks: the per-block numbers converted to Python
        once for all blocks (tolist); each message with its JSON text where every number is
        there, made by the template of its channel and method
        (:class:`~cmsensord.sinks.orders_encoding.OrdersTemplate`), its dict what
        :func:`~cmsensord.monitor.messages.orders` makes (that function builds them without
        ``PRE_ENCODED``: the reference, with the frequencies of all blocks in one array
        operation).  A component's frequency is order x rpm / 60 (the operations of
        :meth:`TrackedComponent.freq`) or its fixed one; a channel's block of no sample (all
        lost: the tracker's prediction alone) is not valid; a message whose block is not valid
        or has a number that is not finite has no text (it is encoded plain: such fields are
        left out of it)."""
        n = len(blocks.start)
        if not n:
            return []
        comps = self.components
        B = self.tracker.block
        assert self.sample0 is not None, "no samples yet"
        base = self.sample0
        stamp_ns = self.clock.stamp_ns
        rpms = blocks.rpm.tolist()
        valid = blocks.valid.tolist()
        t_in = blocks.t_in.tolist()
        rms, amp, missing = blocks.rms.tolist(), blocks.amplitude.tolist(), blocks.missing.tolist()
        names = [ch.name for ch in self.channels]
        out: Out = []
        if not PRE_ENCODED:
            # TrackedComponent.freq of every block: order * rpm / 60 (the same operations), or freq_hz
            freqs = np.where(self._by_order, self._orders * blocks.rpm[:, None] / 60.0, self._fixed_hz).tolist()
            for e in range(n):
                stamp = stamp_ns(base + int(t_in[e]))
                rpm, ok = rpms[e], bool(valid[e])
                for ci, name in enumerate(names):
                    seen = ok and missing[e][ci] < B          # a block of no sample is a prediction: not valid
                    entries = messages.order_entries(comps, freqs[e], rms[e][ci], amp[e][ci], seen)
                    out.append(messages.orders(stamp, name, rpm, seen, method, entries, missing[e][ci] / B))
            return out
        spec = self._freq_spec
        Message = messages.Message
        order_entries = messages.order_entries
        chans = self._channels.get(method) or self._channels_of(method)
        for e in range(n):
            stamp = stamp_ns(base + t_in[e])
            rpm, ok = rpms[e], valid[e]
            freq = [f if o is None else o * rpm / 60.0 for o, f in spec]
            speed = None if rpm != rpm else rpm                 # messages.num
            for (name, topic, fill), r, a, m in zip(chans, rms[e], amp[e], missing[e]):
                mf = m / B
                seen = ok and m < B
                fields = {"channel": name, "speed_rpm": speed, "valid": seen, "method": method,   # messages.orders
                          "orders": order_entries(comps, freq, r, a, seen), "missing_fraction": mf}
                text = None
                if seen and fill is not None:
                    nums = (rpm, *chain.from_iterable(zip(freq, r, a)), mf)
                    if all(map(isfinite, nums)):
                        text = fill % nums
                out.append(Message(topic, "orders", stamp, fields if text is None else EncodedMessage(fields, text)))
        return out

    def _channels_of(self, method: str) -> list[tuple[str, str, str | None]]:
        """Per channel its name, /orders topic and the text template of its messages of
        ``method`` (:meth:`_template`), made once."""
        self._channels[method] = [(ch.name, orders_topic(ch.name), self._template(ci, method))
                                  for ci, ch in enumerate(self.channels)]
        return self._channels[method]

    def _template(self, ci: int, method: str) -> str | None:
        """The text template of channel ``ci``'s /orders messages of ``method``, made once (None:
        that shape has none; a name made of the markers' characters)."""
        key = (ci, method)
        if key not in self._templates:
            self._templates[key] = OrdersTemplate(self.channels[ci].name, method,
                                                  [(c.name, c.order) for c in self.components]).text
        return self._templates[key]
