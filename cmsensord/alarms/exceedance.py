"""A value against alert and danger levels with a deadband (hysteresis).

Per level: exceeded once the value reaches it, and still exceeded until the value
falls below level x (1 - deadband).  The exceedance level is 2 (danger exceeded),
1 (alert exceeded) or 0.  A level that is None is never exceeded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Exceedance"]


@dataclass
class Exceedance:
    deadband: float = 0.05          # fraction of the level
    over: list[bool] = field(default_factory=lambda: [False, False])

    def step(self, value: float, alert: float | None, danger: float | None) -> int:
        """The exceedance level of ``value`` (see module docstring)."""
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
