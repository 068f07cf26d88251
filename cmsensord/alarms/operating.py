"""The machine's operating state from its speed or an indicator's level, and when alarms
are suppressed.

States: ``stopped``, ``starting``, ``running``, ``coasting``.  The reading
(speed in rpm, or the level indicator's value) makes the machine run at or above
``running_above`` and stop below ``stopped_below`` (between them it keeps its
state: hysteresis).  After a start the state is ``starting`` for
``startup_suppress_s``; with a speed, a fall of more than ``coastdown_drop_pct``
below the highest speed since the machine last ran steadily is a coast-down:
``coasting`` for ``coastdown_suppress_s`` (or until it stops; it runs again on
afterwards, with that speed as the new reference).  Alarms are evaluated only in
``running``.  A reading that is absent (no speed) keeps the state.  Source
``none``: always running.  Times are stream stamps [ns].
"""

from __future__ import annotations

from cmsensord.config.alarms import OperatingConfig

__all__ = ["Operating", "STATES"]

STATES = ("stopped", "starting", "running", "coasting")


class Operating:
    """Operating state machine (see module docstring)."""

    def __init__(self, cfg: OperatingConfig):
        self.cfg = cfg
        self.state = "running" if cfg.source == "none" else "stopped"
        self.since_ns: int | None = None     # start of starting / coasting
        self.ref: float | None = None         # highest speed while running
        self.reading: float | None = None

    @property
    def running(self) -> bool:
        return self.state == "running"

    def step(self, t_ns: int, reading: float | None) -> str:
        """The reading at ``t_ns`` (rpm or the level indicator's value; None: unknown); the new state."""
        c = self.cfg
        if c.source == "none" or reading is None:
            return self._timeout(t_ns)
        self.reading = reading
        run_at = c.running_above if c.running_above is not None else 0.0
        stop_at = c.stopped_below if c.stopped_below is not None else run_at
        if self.state == "stopped":
            if reading >= run_at:
                self._go("starting" if c.startup_suppress_s > 0 else "running", t_ns)
                self.ref = reading
            return self.state
        if reading < stop_at:
            self._go("stopped", t_ns)
            return self.state
        if c.source == "speed" and self.state == "running" and c.coastdown_suppress_s > 0 \
                and self.ref is not None and reading < self.ref * (1 - c.coastdown_drop_pct / 100):
            self._go("coasting", t_ns)
        if self.state == "running":
            self.ref = max(self.ref or reading, reading)
        self._timeout(t_ns)
        return self.state

    def shift(self, shift_ns: int) -> None:
        """The stamps were re-anchored by ``shift_ns`` (a step of the wall clock): a suppression
        time running goes on as if there had been none."""
        if self.since_ns is not None:
            self.since_ns += shift_ns

    def _timeout(self, t_ns: int) -> str:
        c = self.cfg
        limit = {"starting": c.startup_suppress_s, "coasting": c.coastdown_suppress_s}.get(self.state)
        if limit is not None and self.since_ns is not None and t_ns - self.since_ns >= limit * 1e9:
            self._go("running", t_ns)
            self.ref = self.reading
        return self.state

    def _go(self, state: str, t_ns: int) -> None:
        self.state, self.since_ns = state, t_ns
