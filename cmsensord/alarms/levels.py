"""A rule's alert and danger levels on one channel at one speed.

A level is given one of three ways: absolute (``alert``, in the indicator's unit),
at the lower boundary of an ISO 10816-3 zone (``alert_zone: C`` is the B/C
boundary of the configured machine group and foundation), or k x the learned
baseline of the indicator on that channel (``alert_x_baseline``; no baseline
learned: no level).  A rule's ``bands`` replace its levels below their
``below_rpm`` (the lowest band that the speed is below); with no speed known, the
rule's own levels apply.
"""

from __future__ import annotations

from typing import Any

from cmsensord.config.alarms import LEVEL_KEYS, AlarmRuleConfig

__all__ = ["rule_levels"]


def _one(src: Any, which: str, zones: tuple[float, float, float], baseline: float | None) -> float | None:
    value, zone, k = (getattr(src, key) for key in LEVEL_KEYS[which])
    if value is not None:
        return float(value)
    if zone is not None:
        return zones["BCD".index(zone)]
    if k is not None and baseline is not None:
        return k * baseline
    return None


def rule_levels(rule: AlarmRuleConfig, speed_rpm: float | None, zones: tuple[float, float, float],
                baseline: float | None) -> tuple[float | None, float | None]:
    """(alert, danger) of ``rule`` at ``speed_rpm``; None where the level is not given."""
    src: Any = rule
    if speed_rpm is not None:
        for band in sorted(rule.bands, key=lambda b: b.below_rpm):
            if speed_rpm < band.below_rpm:
                src = band
                break
    return _one(src, "alert", zones, baseline), _one(src, "danger", zones, baseline)
