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
more than the channels it watches (its ``channels``, else every vibration channel), whose
alarm would never rise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .validation import ConfigError

__all__ = ["channel_refs_error", "check_channel_refs"]

_CODE = "<code>"        # the error's source until a loader or the command names the file


def channel_refs_error(cfg: Any, channels: Sequence[Any]) -> tuple[str, str, Any] | None:
    """(key path, reason, value) of the first rule or bearing naming none of ``channels``
    (:class:`~.settings.ChannelConfig`), or rule whose ``vote`` is more than the channels it
    watches (its own, else every vibration channel)."""
    names = [ch.name for ch in channels]
    have = f"names no channel (channels: {', '.join(names)})"
    for i, r in enumerate(cfg.alarms.rules):
        for c in r.channels:
            if c not in names:
                return f"alarms.rules[{i}].channels", have, c
        watched = r.channels or [ch.name for ch in channels if ch.kind != "microphone"]
        if r.vote > len(watched):
            return (f"alarms.rules[{i}].vote", f"must be at most the {len(watched)} channel(s) the rule "
                    f"watches ({', '.join(watched)}): that many never exceed the level together", r.vote)
    for i, b in enumerate(cfg.bearings):
        if b.channel not in names:
            return f"bearings[{i}].channel", have, b.channel
    return None


def check_channel_refs(cfg: Any, channels: Sequence[Any], source: str = _CODE) -> None:
    """Raise ConfigError (``source``: the file, else the command names it) when a rule or a
    bearing of ``cfg`` names none of ``channels``, or a rule's vote is more than it watches."""
    found = channel_refs_error(cfg, channels)
    if found is not None:
        raise ConfigError(source, *found)
