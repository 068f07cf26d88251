"""Recursive angular-velocity Vold-Kalman order tracking (AV2KF_OT), streaming.

The order tracker of Yeh, Pan & Le ("Online Real-Time Monitoring System through
Using Adaptive Angular-Velocity VKF Order Tracking", section 2, eqs. (10)-(25))
for several channels of one machine at once, with decimation in front, an
optional fixed-lag smoother behind, and per-block RMS/amplitude outputs.  The
derivations, the choices made where the paper is silent, the handling of
missing samples and the measured accuracy are in docs/order_tracker.md.

Modules: :mod:`.components` (what is tracked), :mod:`.antialias` (the
decimator's low-pass), :mod:`.design` (model matrices, steady-state gains), :mod:`.gain_table` (those
gains tabulated against speed),
:mod:`.bandwidth` (r <-> bandwidth), :mod:`.reference` (the per-sample
reference), :mod:`.recursions` (the numpy recursions), :mod:`.state` (outputs
and carried state), :mod:`.decimation` (the input decimated, its missing samples),
:mod:`.blocks` (per-block outputs), :mod:`.smoother` (the fixed-lag smoother),
:mod:`.tracker` (:class:`OrderTracker`).  The compiled kernel is
``cmsensord.dsp._trackerkernel``.  Alarms on the tracked orders are the alarm manager's
rules (``order_<component>`` on ``order.<component>``), not this package's.
"""

from cmsensord.dsp.order_tracker.antialias import MISSING_TAIL
from cmsensord.dsp.order_tracker.bandwidth import bandwidth_to_r, component_r, r_to_bandwidth, time_constant
from cmsensord.dsp.order_tracker.components import DEFAULT_R, TrackedComponent
from cmsensord.dsp.order_tracker.reference import reference_track
from cmsensord.dsp.order_tracker.state import BlockStats, TrackerOutput, TrackerState
from cmsensord.dsp.order_tracker.tracker import OrderTracker, have_kernel

__all__ = [
    "DEFAULT_R",
    "MISSING_TAIL",
    "BlockStats",
    "OrderTracker",
    "TrackedComponent",
    "TrackerOutput",
    "TrackerState",
    "bandwidth_to_r",
    "component_r",
    "have_kernel",
    "r_to_bandwidth",
    "reference_track",
    "time_constant",
]
