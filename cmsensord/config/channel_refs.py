"""The channels that alarm rules and bearings name, against the names the channels have.

An alarm rule's ``channels`` and a bearing's ``channel`` must name channels as they are
called: the configuration's ``channels`` list; without one, the names an imported capture's
import gave them (``cmsensord replay`` and ``calibrate`` of it), else the board's ch0, ch1,
...  With a list the names are known from the file, and :func:`~.loading.config_from_dict`
checks them there; without one they are known once the capture or the board says how many
channels there are, and the monitoring chain's channel set-up checks them then
(:mod:`cmsensord.monitor.channels`).  A name matching no channel would never see a value
(a rule never fires, a bearing's lines are never computed): :func:`check_channel_refs`
raises a one-line :class:`~cmsensord.errors.ConfigError`; and for a rule whose ``vote`` is
more than the channels it watches (:func:`rule_channels`), whose alarm would never rise.

A bearing's lines (``<bearing>.<line>``, and their ratios ``<bearing>.<line>_ratio``) are
computed on the bearing's ``channel`` only: a rule on one watches that channel when it lists no
``channels`` (:func:`rule_channels`), and a rule listing another channel is refused on loading,
by :func:`rules_on_bearing_channels`, whatever the channels are called.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .alarm_indicators import BEARING_VALUES
from .validation import ConfigError

__all__ = ["channel_refs_error", "check_channel_refs", "bearing_of", "rule_channels", "rules_on_bearing_channels"]

_CODE = "<code>"        # the error's source until a loader or the command names the file


def bearing_of(indicator: str, bearings: Sequence[Any]) -> Any | None:
    """The bearing of ``bearings`` (:class:`~.indicators.BearingConfig`) whose line ``indicator``
    is (``<bearing>.<line>``), or None when it is no configured bearing's line."""
    name, dot, line = indicator.rpartition(".")
    if not dot or line not in BEARING_VALUES:
        return None
    return next((b for b in bearings if b.name == name), None)


def rule_channels(rule: Any, channels: Sequence[str], bearings: Sequence[Any] = ()) -> tuple[str, ...]:
    """The channels alarm rule ``rule`` watches: its ``channels``; without them, on a line of one
    of ``bearings`` that bearing's channel, else ``channels`` (every vibration channel)."""
    if rule.channels:
        return tuple(rule.channels)
    bearing = bearing_of(rule.indicator, bearings)
    return (bearing.channel,) if bearing is not None else tuple(channels)


def rules_on_bearing_channels(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: a rule on a bearing's line lists in its ``channels`` only the bearing's
    channel (the line is computed there alone: on any other channel the rule never fires)."""
    for i, r in enumerate(cfg.alarms.rules):
        bearing = bearing_of(r.indicator, cfg.bearings)
        if bearing is None:
            continue
        on = bearing.channel
        off = [c for c in r.channels if c != on]
        if off:
            return (f"alarms.rules[{i}].channels", f"rule {r.name} watches {r.indicator}, and bearing "
                    f"{bearing.name} is on {on} only: give channels: [{on}] (or none), or add a bearing on "
                    f"{off[0]} and a rule on its line", off[0])
    return None


def channel_refs_error(cfg: Any, channels: Sequence[Any]) -> tuple[str, str, Any] | None:
    """(key path, reason, value) of the first rule or bearing naming none of ``channels``
    (:class:`~.settings.ChannelConfig`; the reason names the rule or bearing and the channels),
    or rule whose ``vote`` is more than the channels it watches (:func:`rule_channels`)."""
    names = [ch.name for ch in channels]
    have = f"names no channel (channels: {', '.join(names)})"
    for i, r in enumerate(cfg.alarms.rules):
        for c in r.channels:
            if c not in names:
                return f"alarms.rules[{i}].channels", f"rule {r.name} {have}", c
        watched = rule_channels(r, [ch.name for ch in channels if ch.kind != "microphone"], cfg.bearings)
        if r.vote > len(watched):
            return (f"alarms.rules[{i}].vote", f"must be at most the {len(watched)} channel(s) the rule "
                    f"watches ({', '.join(watched)}): that many never exceed the level together", r.vote)
    for i, b in enumerate(cfg.bearings):
        if b.channel not in names:
            return f"bearings[{i}].channel", f"bearing {b.name} {have}", b.channel
    return None


def check_channel_refs(cfg: Any, channels: Sequence[Any], source: str = _CODE) -> None:
    """Raise ConfigError (``source``: the file, else the command names it) when a rule or a
    bearing of ``cfg`` names none of ``channels``, or a rule's vote is more than it watches."""
    found = channel_refs_error(cfg, channels)
    if found is not None:
        raise ConfigError(source, *found)
