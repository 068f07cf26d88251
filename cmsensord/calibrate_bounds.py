"""The bounds ``cmsensord calibrate`` advises when the healthy period is not steady: the
``--to`` or ``--from`` of its steady stretch (levels within level_alert x their own median), the
``--to`` before a level rise below that, one of them per channel (the earlier ``--to`` when both
are given), and the one bound that keeps every channel's."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cmsensord.observations import Observations
from cmsensord.service.origin import span_line

if TYPE_CHECKING:
    from cmsensord.commission import ChannelResult

__all__ = ["FEW_DECISIONS", "every_channels_bound", "level_warning", "rise_warning"]

#: fewer decisions learned from than this: calibrate warns that the healthy fluctuation is a guess
FEW_DECISIONS = 10


def level_warning(r: ChannelResult, obs: Observations) -> str:
    """What the decisions of the healthy period that are already at the alert level mean, where
    they are, and the ``--to`` or ``--from`` of its longest steady stretch (:func:`_steady_bound`);
    when the level rise's ``--to`` is the earlier, a pointer to the rise's warning, which follows."""
    m, dec = r.model, r.decision_s
    first, last = obs.start_s + m.level_first * dec, obs.start_s + (m.level_last + 1) * dec
    mid = (obs.start_s + obs.end_s) / 2
    where = span_line(obs.meta, first, last)
    span = f"{first:.1f}-{last:.1f} board s" + (f", {where}" if where else "")
    what = ("the machine may already be changing there (a fault starting)" if first >= mid else
            "a start-up or a disturbance" if last <= mid else "the level is not steady over the healthy period")
    within = f"(levels within {r.level_alert:g} x its own median)"
    bound = _steady_bound(r, obs)
    if _rise_first(r, obs):
        advice = "the level already rises before them (next warning)"
    elif bound is None:
        advice = "no stretch of it is steady: choose another healthy period with --from/--to"
    elif bound[0] == "--to":
        advice = f"its steady stretch from the start ends at --to {bound[1]:g} {within}"
    else:
        advice = f"its steady stretch to the end begins at --from {bound[1]:g} {within}"
    return (f"{r.name}: warning: {m.level_flagged} decision(s) of the healthy period are already at "
            f">= {r.level_alert:g} x its baseline (level_alert: severity 0.5) in {span}: {what}; {advice}")


def rise_warning(r: ChannelResult, obs: Observations) -> str:
    """A level rising through the healthy period below the alert level (:func:`level_rise`):
    where, and the ``--to`` that ends the period before it, with why it is advised over the steady
    stretch's later one when that holds the rise too; when the steady stretch holds no rise, its
    ``--to`` (the warning above)."""
    m, dec = r.model, r.decision_s
    at = obs.start_s + m.rise_at * dec
    where = span_line(obs.meta, at, at + dec)
    to = _rise_to(r, obs)
    steady = _flagged_steady(r, obs)
    if to is None:
        before = m.rise_at - m.runin_periods - 1
        advice = f"only {max(0, before)} decision(s) before it: choose a steady period of this machine (--from/--to)"
    elif steady is not None and steady[0] == "--to" and not m.steady_rise:
        advice = "the --to of the warning above leaves it out"
    else:
        advice = f"a period ending before it learns the machine's own level (--to {to:g})"
        if _rise_first(r, obs):
            advice += (f"; the steady stretch from the start, whose levels stay within {r.level_alert:g} x its "
                       "own median, runs on past the rise and would learn it")
    return (f"{r.name}: warning: the level rises through the healthy period: its last quarter's median is "
            f"{m.rise:.2f} x its first quarter's, rising from {at:.1f} board s" + (f" ({where})" if where else "") +
            f": wear or a fault starting, or a change of load; learned from, it raises the baseline and widens every "
            f"margin: {advice}")


def _rise_to(r: ChannelResult, obs: Observations) -> float | None:
    """The ``--to`` (board s, a tenth of a second) that ends the healthy period before its level
    rise, or None without a rise or with fewer than FEW_DECISIONS learned from before it."""
    m = r.model
    if m.rise_at < 0 or m.rise_at - m.runin_periods - 1 < FEW_DECISIONS:
        return None
    return math.floor(round(10 * (obs.start_s + m.rise_at * r.decision_s), 6)) / 10


def _rise_first(r: ChannelResult, obs: Observations) -> bool:
    """Whether both warnings give a ``--to`` and the rise's is the one advised: the steady stretch
    from the start (levels within level_alert x their own median) holds a rise of its own, and the
    rise's ``--to`` is the earlier."""
    to, steady = _rise_to(r, obs), _flagged_steady(r, obs)
    return (to is not None and steady is not None and steady[0] == "--to" and r.model.steady_rise
            and to < steady[1])


def _advised_bound(r: ChannelResult, obs: Observations) -> tuple[str, float] | None:
    """The one bound calibrate advises for channel ``r``: the rise's ``--to`` when it comes first
    (:func:`_rise_first`) or no steady stretch is given, else the steady stretch's; None when
    neither is."""
    steady = _flagged_steady(r, obs)
    to = _rise_to(r, obs)
    if to is not None and (steady is None or _rise_first(r, obs)):
        return "--to", to
    return steady


def _flagged_steady(r: ChannelResult, obs: Observations) -> tuple[str, float] | None:
    """The steady stretch's bound (:func:`_steady_bound`) when the level check gives one (decisions
    of the healthy period at level_alert), else None."""
    return _steady_bound(r, obs) if r.model.level_flagged else None


def _steady_bound(r: ChannelResult, obs: Observations) -> tuple[str, float] | None:
    """(``--to``, board s) of the healthy period's longest steady stretch from its start, or
    (``--from``, board s) of the one to its end, to a tenth of a second within it; None when
    neither is two decisions long."""
    m, dec = r.model, r.decision_s
    if max(m.steady_head, m.steady_tail) < 2:
        return None
    if m.steady_head >= m.steady_tail:
        return "--to", math.floor(round(10 * (obs.start_s + (m.steady_head + 1) * dec), 6)) / 10
    periods = m.periods + m.runin_periods + 1          # with the transient's
    return "--from", math.ceil(round(10 * (obs.start_s + (periods - m.steady_tail) * dec), 6)) / 10


def every_channels_bound(results: list[ChannelResult], obs: Observations) -> str | None:
    """With several channels given a bound (:func:`_advised_bound`), the one ``--to`` (the
    earliest) or ``--from`` (the latest) that keeps each one's, when they agree on which."""
    bounds = [b for r in results if (b := _advised_bound(r, obs)) is not None]
    if len(bounds) < 2 or len({kind for kind, _ in bounds}) != 1:
        return None
    kind = bounds[0][0]
    at = min(v for _, v in bounds) if kind == "--to" else max(v for _, v in bounds)
    return f"every channel's steady stretch: {kind} {at:g}"
