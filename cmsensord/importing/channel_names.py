"""Channel names an import gives: names the daemon can use in its MCAP topics (``/cm/<name>/...``).

A recording's column labels are often not (``Acc X (g)``, ``bearing.gs``): each run of
characters other than letters, digits and ``_`` becomes one ``_`` (``Acc_X_g``), a label
with none of them left is ``chN`` (its channel's index), and a name already taken gets ``_2``,
``_3``, ...  Names given with ``--names`` are the user's own: one that is not a channel name is
an error instead.
"""

from __future__ import annotations

import dataclasses
import re

from cmsensord.config import ChannelConfig, Config, ConfigError

from .errors import ImportFailure
from .sidecar import channel_units

__all__ = ["NAME_RULE", "capture_channels", "channel_names", "checked_names", "imported_channels", "imported_names"]

#: what a channel name may hold: the configuration's rule for channels[].name
NAME_RULE = re.compile(next(f.metadata["pattern"] for f in dataclasses.fields(ChannelConfig) if f.name == "name"))


def channel_names(labels: list[str]) -> tuple[list[str], list[str]]:
    """Names from column labels, and a note for each label that had to change."""
    names: list[str] = []
    taken: set[str] = set()
    suffix: dict[str, int] = {}     # base -> the next _k to try: each label costs one look-up or so
    notes = []
    for i, label in enumerate(labels):
        base = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_") or f"ch{i}"
        name, k = base, suffix.get(base, 2)
        while name in taken:
            name, k = f"{base}_{k}", k + 1
        suffix[base] = k
        names.append(name)
        taken.add(name)
        if name != label:
            notes.append(f"channel {label!r} is named {name} (letters, digits and _ only: the MCAP topics "
                         f"/cm/{name}/...); --names sets other names")
    return names, notes


def checked_names(given: list[str]) -> list[str]:
    """``--names`` as given; a one-line error for one that is not a channel name or comes twice."""
    for name in given:
        if not NAME_RULE.fullmatch(name):
            raise ImportFailure(f"--names: {name!r} is not a channel name: letters, digits and _ only "
                                f"(the MCAP topics /cm/<name>/...)")
    twice = sorted({n for n in given if given.count(n) > 1})
    if twice:
        raise ImportFailure(f"--names: {', '.join(twice)} given twice; every channel needs its own name")
    return given


def imported_names(meta: dict) -> list[str]:
    """The channel names of an imported capture's sidecar ``meta`` (none: []): as they are when
    each is a channel name and none comes twice (the names the import gave, ``--names`` as
    typed); else made names as an import makes them now (a capture imported before may hold
    other labels)."""
    names = [str(n) for n in meta.get("channel_names") or []]
    if all(NAME_RULE.fullmatch(n) for n in names) and len(set(names)) == len(names):
        return names
    return channel_names(names)[0]


def capture_channels(cfg: Config, meta: dict, auto_channels: bool) -> tuple[Config, bool, list[str]]:
    """The channels a replay of an imported capture (its sidecar ``meta``; {}: not an import)
    runs: ``cfg``'s, or with ``auto_channels`` (``cfg`` lists none) the import's, named as it
    named them (:func:`imported_channels`); with whether they are still the board's (``auto``)
    and warnings. The import says each channel's unit (Pa: a microphone's): a configured
    channel whose ``kind`` measures another is a :class:`~cmsensord.errors.ConfigError` (a
    microphone calibrated in Pa fed m/s2 estimates nothing, and says nothing); a channel the
    import holds in Pa that no configuration lists is a warning (monitored as a level)."""
    if auto_channels:
        named = imported_channels(cfg, meta)
        cfg, auto_channels, listed = named, named is cfg, False
    else:
        listed = True
    units = channel_units(meta)
    warnings = []
    for i, ch in enumerate(cfg.channels):
        held = str(units[ch.index]) if ch.index < len(units) else None
        if held is None or held == ch.physical_unit.replace("^", ""):
            continue
        if listed:
            raise ConfigError("<code>", f"channels[{i}].kind", f"{ch.kind}, but the capture holds {ch.name} in "
                              f"{held} (its import's --unit): a microphone's channel is imported in Pa, an "
                              "accelerometer's in an acceleration; re-import it, or set kind", ch.kind)
        warnings.append(f"{ch.name}: the capture holds it in Pa (a microphone's), monitored here as an "
                        "accelerometer's level: list it in --config as kind: microphone with its calibration "
                        "(python -m cmsensord.acoustic_calib)")
    return cfg, auto_channels, warnings


def imported_channels(cfg: Config, meta: dict) -> Config:
    """``cfg`` (which lists no channels) with the channels of an imported capture named as
    its import named them (its sidecar ``meta``'s ``channel_names``, as channel names); ``cfg``
    itself without them."""
    names = imported_names(meta)
    if not names:
        return cfg
    return dataclasses.replace(cfg, channels=tuple(ChannelConfig(name=n, index=i, monitor=cfg.monitor)
                                                   for i, n in enumerate(names)))
