"""Tacho edges -> instantaneous shaft speed and angle at every sample.

The shaft reference of the order tracker: :class:`TachoTracker` turns the
rising edges of the TACHO frames (docs/PROTOCOL.md), streaming, into the speed
(Hz) and the shaft angle (turns) at any sample index, with a validity
flag, events for lost/restored tacho and repaired pulses, and a causal speed.
The method, its delays and its measured accuracy are in docs/tacho.md.

Modules: :mod:`.edges` (edge times, runs, pulse repair, events), :mod:`.gaps`
(intervals across lost TACHO frames), :mod:`.smoothing` (least-squares knots, speed and
angle at every sample), :mod:`.causal` (the causal speed), :mod:`.tracker` (:class:`TachoTracker`).
"""

from cmsensord.dsp.tacho.edges import (
    EXTRA,
    LOST,
    MISSED,
    RESTORED,
    TachoCounters,
    TachoEvent,
    TachoUpdate,
)
from cmsensord.dsp.tacho.tracker import TachoTracker

__all__ = ["TachoEvent", "TachoCounters", "TachoUpdate", "TachoTracker", "LOST", "RESTORED", "MISSED", "EXTRA"]
