"""What the report draws over its trends: channel events as vertical lines, alarm levels as horizontal
ones, the healthy period the baselines were learned from as a shaded band.

Each marked event kind has its own colour and line style and a legend label saying what it is
(:data:`EVENT_STYLES`): a ``failure`` (the severity model's last AKF flags) is a solid line, an
``alarm_danger`` (a configured rule's danger level reached) a dash-dot one. The alert and
danger levels of the alarm rules, as the log's ``/cm/alarms`` table last gave them, are drawn
on the trend of the indicator each rule watches (:func:`alarm_levels`). The healthy period
(:mod:`.healthy`) is a grey hatched band under the trends, on every time axes of its recording
(:func:`healthy_span`): the stretch the baselines and the levels on them were learned from.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cmsensord.report.healthy import LEGEND
from cmsensord.report.log_data import ChannelData

__all__ = ["EVENT_STYLES", "LEVEL_COLOURS", "HEALTHY_COLOUR", "event_lines", "alarm_levels", "healthy_span"]

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
#: the colour of a rule's alert and danger level
LEVEL_COLOURS = {"alert": "#e08a00", "danger": "#b00020"}
#: the colour of the healthy period's band (grey: not a zone, an alarm or an anomaly)
HEALTHY_COLOUR = "#607d8b"


def healthy_span(ax: Any, x0: float, x1: float) -> None:
    """The healthy period from ``x0`` to ``x1`` shaded on ``ax``, under its trends (above the ISO
    zones' colours), with the legend entry :data:`.healthy.LEGEND`."""
    ax.axvspan(x0, x1, facecolor=HEALTHY_COLOUR, alpha=0.16, edgecolor=HEALTHY_COLOUR, hatch="//", lw=0,
               zorder=0.5, label=LEGEND)


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


def alarm_levels(ax: Any, ch: ChannelData, indicators: tuple[str, ...], *,
                 say_indicator: bool = False) -> list[dict[str, Any]]:
    """Each alarm rule's alert and danger levels on ``ax`` for the rules watching one of
    ``indicators`` on this channel: dashed horizontal lines labelled with the rule's name (with
    ``say_indicator`` also the indicator it watches: ``bpfo alert 0.16 (de.bpfo)``).
    Returns what was drawn ({rule, indicator, level, value})."""
    drawn = []
    for rule, (indicator, levels) in sorted(ch.alarm_levels.items()):
        if indicator not in indicators:
            continue
        for level, value in zip(("alert", "danger"), levels):
            if value is not None and np.isfinite(value):
                ax.axhline(value, color=LEVEL_COLOURS[level], lw=1, ls="--",
                           label=f"{rule} {level} {value:g}" + (f" ({indicator})" if say_indicator else ""))
                drawn.append({"rule": rule, "indicator": indicator, "level": level, "value": value})
    return drawn
