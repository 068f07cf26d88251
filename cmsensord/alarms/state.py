"""One alarm's state: the exceedance level in, the alarm level out, with delays and latching.

Levels: 0 normal, 1 alert, 2 danger. For each level L the alarm turns on once the value has
reached L (the input ``reached``, no deadband) for ``on_delay_s`` of stream time without a
break, and off once the input (the exceedance level, with its deadband) has been below L for
``off_delay_s``; the output is the highest level that is on. A latching alarm shows the highest
level it reached until acknowledged; an acknowledgement then drops it to the level that is on
now, or that the value is back at within its on-delay (a dip cleared the level a moment before:
the machine is not back to normal), held while that delay runs, and that episode latches
nothing more: it clears when the value falls, and a rise of the level shown (a new alarm:
danger again after an acknowledged danger fell to alert) latches again. While suppressed
(machine not running) nothing turns on, the timers restart, and the non-latched level is off. A
delay counts the stream's own time: when the stamps are re-anchored (a step of the wall clock)
:meth:`AlarmState.shift` moves its timers with them, so a delay straddling the step lasts as if
there had been none; an input stamped before the start of a delay (stamps gone back
unannounced) restarts it there, never measuring a negative time.

:meth:`AlarmState.resume` puts back what a saved state held (a daemon's restart:
:mod:`.saved`): the latch, the acknowledgement, and the live level at the stop as a
*restored* level, shown until the rule confirms it (the live level reaches it: the same
episode goes on, no new alarm, the acknowledgement kept) or, unconfirmed, for
``RESUME_S`` plus the on-delay (at least the off-delay) of stream time from the first
input; then the alarm shows what the rule says.  A chain that starts again (the severity
index starts at 0 and climbs back over some decisions) thus does not clear and raise again
an alarm that held over the restart.  Suppression drops a restored level.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["LEVELS", "AlarmState", "RESUME_S"]

#: level names, by level
LEVELS = ("normal", "alert", "danger")
#: a restored level waits this long (plus the on-delay) of stream time for the rule to confirm it [s]
RESUME_S = 30.0


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
    acked_ns: int | None = None          # when the acknowledgement in force was given
    acked_by: str | None = None          # who gave it (the user of `cmsensord ack`), if known
    restored: int = 0                    # the live level at a restart's stop, until confirmed
    restored_until: int | None = None    # stamp at which an unconfirmed restored level drops

    @property
    def live(self) -> int:
        """The level that is on now (delays applied, no latch)."""
        return 2 if self.on[1] else 1 if self.on[0] else 0

    @property
    def pending(self) -> int:
        """The highest level whose on-delay is running (the value at it, the level not on yet)."""
        return 2 if self.since[1] is not None and not self.on[1] else \
            1 if self.since[0] is not None and not self.on[0] else 0

    @property
    def level(self) -> int:
        """The level shown: the live level, or the latched one until acknowledged, or the restored
        one until confirmed."""
        return max(self.live, self.latched, self.restored)

    def step(self, t_ns: int, x: int, reached: int | None = None) -> int:
        """The input level ``x`` at ``t_ns`` (``reached``: the level the value itself reached,
        default ``x``; see module docstring); returns the level shown after it."""
        before = self.level
        for i in (0, 1):
            want = (x if self.on[i] or reached is None else reached) >= i + 1
            if want == self.on[i]:
                self.since[i] = None
                continue
            since = self.since[i]
            if since is None or t_ns < since:
                since = self.since[i] = t_ns
            delay = self.on_delay_s if want else self.off_delay_s
            if t_ns - since >= delay * 1e9:
                self.on[i] = want
                self.since[i] = None
        if self.restored:
            if self.restored_until is None:
                self.restored_until = t_ns + round(max(RESUME_S + self.on_delay_s, self.off_delay_s) * 1e9)
            if self.live >= self.restored or t_ns >= self.restored_until:
                self.restored, self.restored_until = 0, None
        if self.acknowledged and self.latched:      # held while its on-delay runs (see ack)
            self.latched = min(self.latched, max(self.live, self.pending))
        return self._shown(t_ns, before)

    def shift(self, shift_ns: int) -> None:
        """The stamps were re-anchored by ``shift_ns``: the times held move with them."""
        self.since = [None if s is None else s + shift_ns for s in self.since]
        if self.restored_until is not None:
            self.restored_until += shift_ns
        if self.changed_ns is not None:
            self.changed_ns += shift_ns
        if self.acked_ns is not None:
            self.acked_ns += shift_ns

    def restart_delays(self) -> None:
        """The input is not known for a while: a delay pending on it starts again with the
        next input (the shown level stays)."""
        self.since = [None, None]

    def suppress(self, t_ns: int) -> int:
        """Suppressed at ``t_ns``: the live level off, the timers restarted."""
        before = self.level
        self.on = [False, False]
        self.since = [None, None]
        if self.acknowledged:                   # a hold of an on-delay (see ack), which restarts
            self.latched = 0
        self.restored, self.restored_until = 0, None
        return self._shown(t_ns, before)

    def ack(self, t_ns: int, by: str | None = None) -> int:
        """Acknowledged at ``t_ns`` (by user ``by``): the latch drops to the live level, or to the
        level whose on-delay runs, held while it does; returns the level shown."""
        before = self.level
        self.latched = min(self.latched, self.pending) if self.latch else 0
        self.acknowledged = max(self.live, self.latched, self.restored) > 0
        self.acked_ns, self.acked_by = (t_ns, by) if self.acknowledged else (None, None)
        return self._shown(t_ns, before)

    def resume(self, live: int, latched: int, acknowledged: bool, changed_ns: int | None,
               acked: tuple[int | None, str | None] = (None, None)) -> None:
        """Put back a saved state: the level ``live`` as the restored level (see module docstring),
        the latch at ``latched``, the acknowledgement (and its time and user)."""
        self.restored, self.restored_until = live, None
        self.latched, self.changed_ns = (0 if acknowledged else latched), changed_ns
        self.acknowledged = acknowledged and self.level > 0
        self.acked_ns, self.acked_by = acked if self.acknowledged else (None, None)

    def _shown(self, t_ns: int, before: int) -> int:
        if self.latch and not self.acknowledged:   # an acknowledged episode latches nothing more
            self.latched = max(self.latched, self.live)
        now = self.level
        if now > before or now == 0:
            self.acknowledged = False
            self.acked_ns = self.acked_by = None
            if self.latch:                          # a rise of the level shown (a new alarm) latches again
                self.latched = max(self.latched, self.live)
        if now != before:
            self.changed_ns = t_ns
        return now
