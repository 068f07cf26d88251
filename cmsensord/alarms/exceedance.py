"""A value against alert and danger levels with a deadband (hysteresis).

Per level: exceeded once the value reaches it, and still exceeded until the value
falls below level x (1 - deadband).  The exceedance level is 2 (danger exceeded),
1 (alert exceeded) or 0; ``reached`` is the level the latest value itself is at or above (no
deadband): an alarm's on-delay counts that, its off-delay the exceedance level
(:class:`~cmsensord.alarms.state.AlarmState`).  A level that is None is never exceeded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Exceedance"]


@dataclass
class Exceedance:
    deadband: float = 0.05          # fraction of the level
    over: list[bool] = field(default_factory=lambda: [False, False])
    reached: int = 0                # the level the latest value is at or above, no deadband

    def step(self, value: float, alert: float | None, danger: float | None) -> int:
        """The exceedance level of ``value`` (see module docstring); ``reached`` set too."""
        self.reached = 2 if danger is not None and value >= danger else 1 if alert is not None and value >= alert else 0
        for i, level in enumerate((alert, danger)):
            if level is None:
                self.over[i] = False
            elif value >= level:
                self.over[i] = True
            elif value < level * (1.0 - self.deadband):
                self.over[i] = False
        return 2 if self.over[1] else 1 if self.over[0] else 0

    def reset(self) -> None:
        self.over = [False, False]
        self.reached = 0
