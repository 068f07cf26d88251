"""``cmsensord calibrate``: alarm levels the healthy period itself reaches, held back by a delay.

Calibrate replays the healthy period with the site file it wrote and warns of each alarm
raised there.  An alarm with an ``on_delay_s`` can stay quiet over a period whose values
reach its level again and again, each time for less than the delay: its level then sits
inside the machine's healthy scatter, and the first healthy run as long as the delay raises
it (FEMTO Bearing1_1's BPFO ratio at 2 x its median over 0.1-s records: 3.6 % of the healthy
records reach it, one at a time, against the 4 in a row of a 0.3-s delay; raised at 39.5 % of
life, on records like the healthy ones).  :func:`thin_margins` says so, per alarm, with what
the healthy values reached and the level above them.

The level it advises is judged over a year of running, not over the healthy period: a rule
whose on-delay needs k values in a row at its level (the delay runs from the first of them: k is
the on-delay over the values' interval, plus one) raises a false alarm wherever k healthy values
in a row reach it.  Taking the values as independent, with a share p of them at the level,
such runs come about N p^k times in the N values of a year; a false alarm in a year is kept below
a probability of FALSE_ALARMS_A_YEAR (10 %) by p <= (0.1 / N)^(1/k).  With an on-delay that needs two
to four values that share is below 1 % (1-s records: 4 values 0.75 %, 3 values 0.15 %, 2 values
0.006 %), so
a level above 99 % of the healthy values still raises a false alarm every few days; the level
advised is above that share of the healthy values, at most SCATTER_SHARE, and the highest healthy
value when the period holds too few values to show a share that small (n values vouch for no
share below 1 / (n + 1), the chance that a value to come exceeds the highest of n).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cmsensord.alarms import Judged

__all__ = ["FALSE_ALARMS_A_YEAR", "SCATTER_SHARE", "thin_margins"]

#: a level more of the healthy values reach than this share sits inside the machine's healthy
#: scatter (a statistical alarm level is above at least 99 % of them: mean + 2.3 standard
#: deviations of a normal scatter)
SCATTER_SHARE = 0.01
#: the expected false alarms a year of running that a level advised keeps below (a 10 % chance
#: of one in a year), with the healthy values taken as independent
FALSE_ALARMS_A_YEAR = 0.1
#: seconds of running a year
YEAR_S = 365.0 * 86400.0


def _runs(over: np.ndarray) -> int:
    """The longest run of True in ``over``."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], over.astype(np.int8), [0]))))
    return int((edges[1::2] - edges[::2]).max()) if edges.size else 0


def _level_of(rule: Any, alert: float | None, danger: float | None) -> tuple[str, float, float | None] | None:
    """(which, level, k) of the lowest level in force: alert, else danger; ``k`` the rule's
    multiple of the baseline when it gives that level so (no speed bands), else None."""
    which, level = ("alert", alert) if alert is not None else ("danger", danger)
    if level is None:
        return None
    k = getattr(rule, f"{which}_x_baseline")
    return which, float(level), (float(k) if k is not None and not rule.bands else None)


def _suggest(which: str, value: float, base: float | None) -> str:
    """The level to set above ``value``: as a multiple of the baseline (to a tenth, above it) when
    the rule gives one."""
    if not base:
        return f"{which} above {value:.4g}"
    k = np.ceil(value / base * 10) / 10
    return f"{which}_x_baseline {k + 0.1 if k * base <= value else k:.1f} or more"


def _series(judged: Judged, alarm: str, vote: int, start_s: float, end_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(board seconds, multiples of the level in force) of ``alarm`` in the healthy period (start_s,
    end_s]: one channel's values as judged; of a vote-N alarm, at each stamp the N-th highest of its
    channels' newest values (its vote reaches the level where that one does)."""
    kept = []
    for ch, stamps in judged.stamps[alarm].items():
        at = (np.frombuffer(stamps, np.int64) - judged.origin_ns) / 1e9
        keep = (at > start_s + 1e-3) & (at <= end_s + 1e-3)
        r = np.frombuffer(judged.ratios[alarm][ch], np.float64)[keep]
        kept.append((at[keep], np.where(np.isnan(r), -np.inf, r)))
    if vote <= 1 or len(kept) < vote:
        return (kept[0] if len(kept) == 1 and vote <= 1 else (np.empty(0), np.empty(0)))
    t = np.unique(np.concatenate([at for at, _ in kept]))
    newest = np.full((t.size, len(kept)), -np.inf)
    for j, (at, r) in enumerate(kept):
        i = np.searchsorted(at, t, side="right") - 1
        newest[i >= 0, j] = r[i[i >= 0]]
    return t, np.sort(newest, axis=1)[:, -vote]


def _shown(rule: Any, which: str, level: float, k: float | None) -> tuple[str, float, Any, Any]:
    """How a warning of ``rule`` says its level and values: (its level, the value of a multiple 1
    of the level, a value as text, the level to set above a value)."""
    vote = f", reached on {rule.vote} of its channels at once," if rule.vote > 1 else ""
    if rule.bands:                      # the level in force goes with the speed
        return (f"its {which} levels (by speed band){vote}", 1.0, lambda v: f"{v:.3g} x the level in force",
                lambda v: f"{which} levels {np.floor(v * 10) / 10 + 0.1:.1f} times as high or more")
    if rule.vote > 1 and k:             # each channel against its own baseline
        return (f"its {which} level ({k:g} x each channel's baseline){vote}", k, lambda v: f"{v:.3g} x baseline",
                lambda v: _suggest(which, v, 1.0))
    base = level / k if k else None
    return (f"its {which} level {level:.4g}" + (f" ({k:g} x baseline)" if k else "") + vote, level,
            lambda v: f"{v:.4g}" + (f" ({v / base:.3g} x baseline)" if base else ""),
            lambda v: _suggest(which, v, base))


def _yearly(share: float, need: int, step: float) -> float:
    """Runs of ``need`` values in a row at the level in a year of values every ``step`` s, a
    ``share`` of them at it, taken as independent (N p^k)."""
    return YEAR_S / step * share ** need


def _allowed(need: int, step: float) -> float:
    """The share of values at a level that keeps its runs of ``need`` below FALSE_ALARMS_A_YEAR in a
    year (:func:`_yearly` solved for p), and at most SCATTER_SHARE."""
    return min(SCATTER_SHARE, (FALSE_ALARMS_A_YEAR * step / YEAR_S) ** (1.0 / need))


def _line(alarm: str, rule: Any, t: np.ndarray, r: np.ndarray, which: str, level: float,
          k: float | None) -> str | None:
    """The warning of ``alarm`` whose healthy values ``r`` (multiples of the level in force, at
    board seconds ``t``) reach ``level`` (None: its margin is not thin, see :func:`thin_margins`):
    more than SCATTER_SHARE of them do, or so many that runs of its on-delay's values come
    FALSE_ALARMS_A_YEAR times a year or more, or a run came within one value of the delay."""
    over = r >= 1.0
    n, longest = int(np.count_nonzero(over)), _runs(over)
    step = float(np.median(np.diff(np.unique(t)))) if np.unique(t).size > 1 else 0.0
    # the delay runs from the first value at the level: it is over at the value on_delay_s after it
    need = int(np.ceil(rule.on_delay_s / step - 1e-9)) + 1 if step > 0 else 1
    scatter = n > SCATTER_SHARE * r.size
    yearly = _yearly(n / r.size, need, step) if step > 0 else 0.0
    if not (scatter or yearly >= FALSE_ALARMS_A_YEAR or longest >= need - 1):
        return None
    said, unit, text, fix_at = _shown(rule, which, level, k)
    noun = "time(s)" if rule.vote > 1 else "value(s)"
    top = float(r.max()) * unit
    share = _allowed(need, step) if step > 0 else SCATTER_SHARE
    above = int(share * r.size)                       # healthy values a level may leave above it
    high = float(np.sort(r)[r.size - 1 - above]) * unit
    where = (f"within the healthy period's scatter (more than {100 * SCATTER_SHARE:g} % of its {noun[:-3]}s reach it)"
             if scatter else f"reached by {100.0 * n / r.size:.2g} % of the healthy {noun[:-3]}s"
             if yearly >= FALSE_ALARMS_A_YEAR else "reached by a healthy run one value short of its on-delay")
    runs = f" (as independent values, {yearly:.2g} such runs a year)" if step > 0 else ""
    if above:
        fix = f"above {100 * (1 - share):.4g} % of the healthy {noun[:-3]}s ({fix_at(high)})"
    else:
        fix = (f"above the healthy period's highest ({fix_at(top)})" + (
            f"; {r.size} healthy {noun[:-3]}s cannot show the level {need} in a row needs (reached by under "
            f"{100 * share:.2g} % of them, for under {FALSE_ALARMS_A_YEAR:g} false alarms a year): a longer healthy "
            "period shows it" if share * r.size < 1 and (scatter or yearly >= FALSE_ALARMS_A_YEAR) else ""))
    return (f"alarm {alarm}: warning: thin margin: {said} is {where}: {n} of {r.size} {noun} there "
            f"({100.0 * n / r.size:.1f} %), the highest {text(top)}, in runs of up to {longest} of the {need} in a "
            f"row its on_delay_s {rule.on_delay_s:g} needs{runs}: only the delay kept it quiet, and a healthy day with "
            "a longer run raises it; set the level " + fix + ", or a longer on_delay_s")


def thin_margins(judged: Judged, rules: dict[str, Any], start_s: float, end_s: float, warned: set[str]) -> list[str]:
    """A warning per alarm not in ``warned`` (those raised or standing in the healthy period,
    said already) whose values judged in the healthy period (start_s, end_s] board seconds
    (``judged``; ``rules``: by name) reach its lowest level in force, held back by its
    ``on_delay_s`` alone, and either more than SCATTER_SHARE of them do (the level is inside the
    healthy scatter) or a run of them came within one value of the delay.  Each value is judged
    against the level in force for it (its channel's baseline, its speed band); a vote-N alarm's
    at each time by the N-th highest of its channels."""
    lines = []
    for alarm in judged.stamps:
        rule = rules.get(alarm.split("/")[0])
        found = _level_of(rule, *judged.levels[alarm]) if rule is not None and alarm not in warned else None
        if rule is None or found is None:
            continue
        t, r = _series(judged, alarm, rule.vote, start_s, end_s)
        line = _line(alarm, rule, t, r, *found) if np.any(r >= 1.0) else None
        if line:
            lines.append(line)
    return lines
