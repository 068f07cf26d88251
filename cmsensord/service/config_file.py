"""The daemon's configuration file as it was when the daemon loaded it, read again at a SIGHUP.

A SIGHUP (``systemctl reload``) starts a new log file and applies no setting: the daemon reads its
configuration once, at start.  An operator who edited the file and reloaded would otherwise see
nothing happen and take the old thresholds for the new ones.  :meth:`ConfigFile.on_reload` reads
the file again and says, in one warning line, what it finds: settings that differ from the running
ones (named, up to :data:`SHOWN`) and how to apply them (a restart, which keeps alarm latches and
acknowledgements), or a file that does not load, whose error a restart would stop the daemon on
(exit 78, not restarted by the unit), to be fixed first.  A file whose settings are the running
ones (an edited comment, no edit) is not mentioned.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from cmsensord.config import Config, config_to_dict, load_config
from cmsensord.errors import ConfigError

__all__ = ["ConfigFile", "changed_settings"]

#: changed settings named in the warning line; more are counted
SHOWN = 3


def _flat(value: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    """(key path, value) of every leaf of a settings dict: ``alarms.rules[1].alert``."""
    if isinstance(value, dict):
        for key, sub in value.items():
            yield from _flat(sub, f"{path}.{key}" if path else str(key))
    elif isinstance(value, (list, tuple)) and value and all(isinstance(v, dict) for v in value):
        for i, sub in enumerate(value):
            yield from _flat(sub, f"{path}[{i}]")
    else:
        yield path, value


def changed_settings(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """The settings ``new`` gives other values than ``old``, each as ``key old -> new`` (a key only
    one of them has: ``(none)`` for the other), in the order of the settings."""
    a, b = dict(_flat(old)), dict(_flat(new))
    out = []
    for key in [*a, *(k for k in b if k not in a)]:
        if a.get(key, _NONE) != b.get(key, _NONE):
            out.append(f"{key} {_text(a.get(key, _NONE))} -> {_text(b.get(key, _NONE))}")
    return out


_NONE = object()


def _text(value: Any) -> str:
    return "(none)" if value is _NONE else str(value)


@dataclass(frozen=True)
class ConfigFile:
    """The ``--config`` file of the daemon and the settings it held at start."""

    path: str
    loaded: Config

    def on_reload(self) -> str | None:
        """The warning line for a SIGHUP (None: the file holds the running settings)."""
        try:
            now = load_config(self.path)
        except ConfigError as exc:
            return (f"{self.path} changed since the daemon started and does not load: "
                    f"{str(exc).removeprefix(exc.source + ': ')}; a reload applies no setting, and a restart "
                    "would stop the daemon (exit 78): fix the file first")
        changes = changed_settings(config_to_dict(self.loaded), config_to_dict(now))
        if not changes:
            return None
        more = f" and {len(changes) - SHOWN} more" if len(changes) > SHOWN else ""
        return (f"{self.path} changed since the daemon started ({', '.join(changes[:SHOWN])}{more}): not "
                "applied, a reload only starts a new log file; restart the daemon to apply it "
                "(systemctl restart cmsensord: alarm latches and acknowledgements are kept)")
