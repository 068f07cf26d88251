"""RMS level alarms with hysteresis on the tracker's per-block outputs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cmsensord.dsp.order_tracker.components import TrackedComponent
from cmsensord.dsp.order_tracker.state import BlockStats


@dataclass(frozen=True)
class AlarmEvent:
    kind: str          # "onset" or "clear"
    component: str
    channel: int
    block_start: int   # tracker-sample index of the block that changed the state
    rpm: float
    rms: float
    level: float


class OrderAlarm:
    """RMS level alarm per (channel, component) with hysteresis.

    ``levels``: {component name: RMS level}.  An alarm sets when a valid block's
    RMS reaches the level and clears when it falls below level x (1 - hysteresis).
    Invalid blocks (speed gate) change nothing.  :meth:`update` returns the
    transitions, with the block's speed.
    """

    def __init__(self, components: Sequence[TrackedComponent], levels: dict[str, float], *,
                 n_channels: int = 1, hysteresis: float = 0.2):
        names = [c.name for c in components]
        unknown = sorted(set(levels) - set(names))
        if unknown:
            raise ValueError(f"levels: unknown components {unknown}; tracked: {names}")
        if not 0 <= hysteresis < 1:
            raise ValueError(f"hysteresis: expected in [0, 1), got {hysteresis}")
        self.names = names
        self.levels = {n: float(v) for n, v in levels.items()}
        self.hysteresis = float(hysteresis)
        self.active = np.zeros((int(n_channels), len(names)), dtype=bool)

    def update(self, blocks: BlockStats) -> list[AlarmEvent]:
        events = []
        for e in range(len(blocks.start)):
            if not blocks.valid[e]:
                continue
            for k, name in enumerate(self.names):
                if name not in self.levels:
                    continue
                lev = self.levels[name]
                for ch in range(self.active.shape[0]):
                    v = float(blocks.rms[e, ch, k])
                    if not self.active[ch, k] and v >= lev:
                        self.active[ch, k] = True
                        events.append(AlarmEvent("onset", name, ch, int(blocks.start[e]),
                                                 float(blocks.rpm[e]), v, lev))
                    elif self.active[ch, k] and v < lev * (1.0 - self.hysteresis):
                        self.active[ch, k] = False
                        events.append(AlarmEvent("clear", name, ch, int(blocks.start[e]),
                                                 float(blocks.rpm[e]), v, lev))
        return events
