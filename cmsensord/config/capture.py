"""Settings of event-triggered captures (``capture``): which events keep the signal around them.

A capture keeps ``pre_s`` seconds before and ``post_s`` seconds after its trigger of
each channel's RAW samples (RMS mode: the 100 Hz block RMS), written to the log with
its spectrum and envelope spectrum (:mod:`cmsensord.monitor.capture`).  ``cmsensord
capture-now`` asks the running daemon for one (trigger ``manual``) whenever captures are
on (any trigger, ``manual`` alone included, or ``every_s``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from .validation import Rule, setting, validate

__all__ = ["CaptureConfig", "MIN_EVERY_S", "MAX_EVERY_S", "TRIGGER_KINDS", "OPERATING_STATES",
           "capture_sees_operating", "capture_akf_in_bank"]

#: event kinds that can trigger a capture (the alarm manager's kinds included), and ``manual``
#: (only ``cmsensord capture-now``: it keeps the ring without any event triggering)
TRIGGER_KINDS = ("alarm_alert", "alarm_danger", "alarm_clear", "severity_change", "anomaly_onset",
                 "failure", "time_base", "tacho_lost", "operating_state", "manual")
#: the shortest periodic capture interval [s]: one sample at the board's 25000 Hz (docs/PROTOCOL.md);
#: a stream slower than one tick a sample ticks once a sample (RMS mode: once a block)
MIN_EVERY_S = 1 / 25000
#: the longest periodic capture interval [s]: a year
MAX_EVERY_S = 365 * 86400

#: the operating states an ``operating_state`` trigger may be restricted to
OPERATING_STATES = ("stopped", "starting", "running", "coasting")


def _known_triggers(obj: Any) -> tuple[str, str, Any] | None:
    for kind in obj.triggers:
        if kind == "order_alarm":       # a kind the daemon never writes: order alarms are alarm-manager rules
            return ("triggers", "order_alarm events are no longer written: order alarms are rules "
                    "order_<name> of the alarm manager, use alarm_alert / alarm_danger", kind)
        if kind not in TRIGGER_KINDS:
            return "triggers", f"unknown trigger {kind!r} (one of {', '.join(TRIGGER_KINDS)})", kind
    for state in obj.operating_states:
        if state not in OPERATING_STATES:
            return ("operating_states", f"unknown operating state {state!r} (one of "
                    f"{', '.join(OPERATING_STATES)})", state)
    return None


def _every_s_a_step(obj: Any) -> tuple[str, str, Any] | None:
    if 0 < obj.every_s < MIN_EVERY_S or obj.every_s > MAX_EVERY_S:
        return ("every_s", f"must be 0 (none) or from {MIN_EVERY_S:g} s (one sample at the board's 25000 Hz) "
                f"to {MAX_EVERY_S:,.0f} s (a year)", obj.every_s)
    return None


@dataclass(frozen=True)
class CaptureConfig:
    """Which events trigger a capture, how long it is and how much may be kept."""

    triggers: tuple[str, ...] = setting((), "event kinds that trigger a capture (none: only every_s)")
    anomaly_akf: int = setting(0, "anomaly_onset triggers only for this AKF_n (1..n); 0: any", ge=0)
    operating_states: tuple[str, ...] = setting(
        (), "operating_state triggers only on entering these states (stopped, starting, running, "
        "coasting); none: every change")
    every_s: float = setting(0.0, "also a periodic capture every this many seconds of board time, at "
                             "least one sample (4e-05 s) and at most a year; 0: none", ge=0)
    pre_s: float = setting(10.0, "seconds kept before the trigger", gt=0, le=120)
    post_s: float = setting(10.0, "seconds kept after the trigger", gt=0, le=120)
    min_interval_s: float = setting(60.0, "at most one capture per channel in this many seconds", ge=0)
    max_mb_per_hour: float = setting(200.0, "captures written per hour of board time at most [MB]", gt=0)

    _RULES: ClassVar[tuple[Rule, ...]] = (_known_triggers, _every_s_a_step)

    def __post_init__(self) -> None:
        validate(self)

    @property
    def enabled(self) -> bool:
        return bool(self.triggers) or self.every_s > 0


def capture_sees_operating(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: an ``operating_state`` trigger needs an operating state to change
    (``alarms.operating.source`` speed or level, the alarm manager enabled)."""
    if "operating_state" in cfg.capture.triggers and (cfg.alarms.operating.source == "none"
                                                       or not cfg.alarms.enabled):
        return ("capture.triggers", "operating_state needs alarms.operating.source speed or level "
                "(and alarms.enabled)", "operating_state")
    return None


def capture_akf_in_bank(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: with an ``anomaly_onset`` trigger, ``anomaly_akf`` names an AKF of the bank
    (at most ``monitor.n``, and each channel's ``n``); AKF_n of a larger n is never flagged, so
    the trigger would never fire.  Without that trigger the setting is not used."""
    k = cfg.capture.anomaly_akf
    if "anomaly_onset" not in cfg.capture.triggers or not k:
        return None
    never = f"the bank has no AKF_{k}, so the anomaly_onset trigger never fires"
    if k > cfg.monitor.n:
        return "capture.anomaly_akf", f"must be <= monitor.n = {cfg.monitor.n}: {never}", k
    for i, ch in enumerate(cfg.channels):
        if k > ch.monitor.n:
            return "capture.anomaly_akf", f"must be <= channels[{i}].n = {ch.monitor.n}: {never}", k
    return None
