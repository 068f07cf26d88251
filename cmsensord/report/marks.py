"""What the report draws over its trends: channel events as vertical lines.

Each marked event kind has its own colour and line style and a legend label saying what it is
(:data:`EVENT_STYLES`): a ``failure`` (the severity model's last AKF flags) is a solid line, an
``alarm_danger`` (a configured rule's danger level reached) a dash-dot one.
"""

from __future__ import annotations

from typing import Any

__all__ = ["EVENT_STYLES", "event_lines"]

#: channel events drawn as vertical lines: kind -> (colour, line style, legend label)
EVENT_STYLES: dict[str, tuple[str, str, str]] = {
    "failure": ("#b00020", "-", "failure (the severity model: its last AKF flags)"),
    "failure_clear": ("#2e7d32", "-", "failure_clear"),
    "alarm_danger": ("#d81b60", "-.", "alarm_danger (a rule's danger level reached)"),
    "alarm_alert": ("#e08a00", "--", "alarm_alert (a rule's alert level reached)"),
    "alarm_clear": ("#2e7d32", ":", "alarm_clear"),
    "order_alarm": ("#6a1b9a", "--", "order_alarm"),
    "capture": ("#1565c0", "--", "capture"),
    "tacho_lost": ("#555555", "--", "tacho_lost"),
}


def event_lines(ax: Any, events: list[tuple[float, str]]) -> None:
    """Vertical lines at ``events`` ((x, kind) of this channel's and the daemon's events), one
    legend entry per kind drawn."""
    shown: set[str] = set()
    for x, kind in events:
        style = EVENT_STYLES.get(kind)
        if style is None:
            continue
        colour, ls, label = style
        ax.axvline(x, color=colour, lw=1.6 if ls == "-" else 1.2, ls=ls, label=label if kind not in shown else None)
        shown.add(kind)
