"""The shaft speed: TACHO frames (docs/PROTOCOL.md type 4) of the configured input ->
:class:`~cmsensord.dsp.tacho.TachoTracker`, created once a STATUS announces a tacho.

Until then at most ``TACHO_WAIT_FRAMES`` of the newest TACHO frames wait.  The
tracker's events (pulses lost, missed, restored ...) are returned as events;
the speed is read by the order chain and, as the decisions' f_r, by the
severity chain (:meth:`Shaft.period_f_r`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cmsensord.config import Config
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import Event
from cmsensord.protocol import Frame, Status, decode_tacho

if TYPE_CHECKING:
    from cmsensord.dsp.tacho import TachoTracker

#: TACHO frames kept while no tacho tracker exists (no STATUS announcing one yet)
TACHO_WAIT_FRAMES = 200


class Shaft:
    """TACHO frames -> tacho tracker (see module docstring)."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.waiting: list[Frame] = []
        self.tacho: TachoTracker | None = None  # once STATUS announces a tacho

    def add(self, f: Frame) -> None:
        """A TACHO frame of any input; only the configured one is kept."""
        if f.chan == self.cfg.tacho.input:
            self.waiting.append(f)
            if len(self.waiting) > TACHO_WAIT_FRAMES and self.tacho is None:
                del self.waiting[0]             # no STATUS yet: keep only the newest

    def ensure(self, status: Status | None, clock: BlockClock) -> bool:
        """Create the tracker once the board has said it has a tacho; True when there is one."""
        if self.tacho is None and status is not None and status.tacho_inputs > 0:
            from cmsensord.dsp.tacho import TachoTracker

            t = self.cfg.tacho
            ppr = t.ppr or status.tacho_ppr
            h = max(1, round(t.smoothing_revs * ppr))
            m = min(64, max(2, round(t.causal_revs * ppr)))
            self.tacho = TachoTracker(clock.fs, ppr, block_len=clock.block_len, half_window=h,
                                      timeout_s=t.timeout_s, causal_window=m)
        return self.tacho is not None

    def tracker(self) -> TachoTracker:
        """The tracker; only called once :meth:`ensure` has returned True."""
        assert self.tacho is not None, "no tacho tracker before ensure()"
        return self.tacho

    def feed(self, clock: BlockClock) -> list[Event]:
        """The waiting TACHO frames -> the tracker; its events (and bad payloads)."""
        frames, self.waiting = self.waiting, []
        t0 = np.fromiter((f.t0_unwrapped for f in frames), dtype=np.int64, count=len(frames))
        edges, events = [], []
        for f in frames:
            try:
                edges.append(decode_tacho(f.payload))
            except ValueError as exc:
                events.append(Event("decode_error", None, f"bad TACHO payload at byte {f.offset}: {exc}"))
                edges.append(np.empty(0, dtype=np.uint32))
        u = self.tracker().update(t0, edges)
        return events + [Event(ev.kind, None, ev.message, clock.stamp_ns(int(ev.sample)),
                               {"count": int(ev.count)}) for ev in u.events]

    def final_slot(self, clock: BlockClock) -> int:
        """The first observation slot whose speed is not final yet."""
        return int((self.tracker().final_until - clock.slot_t0(0)) // clock.block_len)

    def period_f_r(self, clock: BlockClock, cfg_f_r: np.ndarray, end_slot: int, period: int) -> np.ndarray:
        """Mean tacho speed [Hz] over the decision period ending at ``end_slot``, per channel
        (the configured ``cfg_f_r`` where the tacho has no valid speed)."""
        slots = np.arange(end_slot - period, end_slot)
        hz, _, ok = self.tracker().evaluate(clock.slot_t0(slots))
        if ok.mean() < 0.5:
            return cfg_f_r
        return np.full(len(cfg_f_r), float(np.mean(hz[ok])))
