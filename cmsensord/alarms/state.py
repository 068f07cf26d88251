"""One alarm's state: the exceedance level in, the alarm level out, with delays and latching.

Levels: 0 normal, 1 alert, 2 danger.  For each level L the alarm turns on once
the input has been at or above L for ``on_delay_s`` of stream time, and off once
it has been below L for ``off_delay_s``; the output is the highest level that is
on.  A latching alarm shows the highest level it reached until acknowledged; an
acknowledgement then drops it to the level that is on now.  While suppressed
(machine not running) nothing turns on, the timers restart, and the non-latched
level is off.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["LEVELS", "AlarmState"]

#: level names, by level
LEVELS = ("normal", "alert", "danger")


@dataclass
class AlarmState:
    """The delays and the latch of one alarm (see module docstring); times in ns of stream time."""

    on_delay_s: float = 0.0
    off_delay_s: float = 0.0
    latch: bool = False
    on: list[bool] = field(default_factory=lambda: [False, False])       # per level 1, 2
    since: list[int | None] = field(default_factory=lambda: [None, None])  # input's side of L changed at
    latched: int = 0
    acknowledged: bool = False
    changed_ns: int | None = None        # stamp of the newest change of the shown level

    @property
    def live(self) -> int:
        """The level that is on now (delays applied, no latch)."""
        return 2 if self.on[1] else 1 if self.on[0] else 0

    @property
    def level(self) -> int:
        """The level shown: the live level, or the latched one until acknowledged."""
        return max(self.live, self.latched)

    def step(self, t_ns: int, x: int) -> int:
        """The input level ``x`` at ``t_ns``; returns the level shown after it."""
        before = self.level
        for i in (0, 1):
            want = x >= i + 1
            if want == self.on[i]:
                self.since[i] = None
                continue
            since = self.since[i]
            if since is None:
                since = self.since[i] = t_ns
            delay = self.on_delay_s if want else self.off_delay_s
            if t_ns - since >= delay * 1e9:
                self.on[i] = want
                self.since[i] = None
        return self._shown(t_ns, before)

    def suppress(self, t_ns: int) -> int:
        """Suppressed at ``t_ns``: the live level off, the timers restarted."""
        before = self.level
        self.on = [False, False]
        self.since = [None, None]
        return self._shown(t_ns, before)

    def ack(self, t_ns: int) -> int:
        """Acknowledged at ``t_ns``: the latch drops to the live level; returns the level shown."""
        before = self.level
        self.latched = 0
        self.acknowledged = self.live > 0
        return self._shown(t_ns, before)

    def _shown(self, t_ns: int, before: int) -> int:
        if self.latch:
            self.latched = max(self.latched, self.live)
        now = self.level
        if now > before:
            self.acknowledged = False
        if now != before:
            self.changed_ns = t_ns
        if now == 0:
            self.acknowledged = False
        return now
