"""The daemon's configuration file as it was when the daemon loaded it, read again at a SIGHUP.

A SIGHUP (``systemctl reload``) starts a new log file and applies no setting: the daemon reads its
configuration once, at start.  An operator who edited the file and reloaded would otherwise see
nothing happen and take the old thresholds for the new ones.  :meth:`ConfigFile.on_reload` reads
the file again and says, in one warning line, what it finds: settings that differ from the running
ones (named, up to :data:`SHOWN`) and how to apply them (a restart, which keeps alarm latches and
acknowledgements; a microphone calibration the configuration names, edited since the daemon
read it, is such a setting too), or a file that does not load, whose error a restart would stop
the daemon on (exit 78), to be fixed first: the file itself when it was edited, else a file it names (an MQTT
password or TLS file, a microphone calibration) that broke since, the configuration's text
unchanged.  A file whose settings are the running ones (an edited comment, no edit) is not mentioned.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from cmsensord.config import Config, config_to_dict, load_config
from cmsensord.errors import ConfigError

__all__ = ["ConfigFile", "changed_settings"]

#: changed settings named in the warning line; more are counted
SHOWN = 3
#: the most of the file's text kept at start (a configuration is a few kB; a longer one is not compared)
MAX_TEXT = 1 << 20


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
    """The ``--config`` file of the daemon, the settings it held at start and its text then
    (None: not read)."""

    path: str
    loaded: Config
    text: bytes | None = None

    @classmethod
    def at_start(cls, path: str, loaded: Config) -> ConfigFile:
        """The file at ``path`` as the daemon loaded it (``loaded``), its text read now (None past
        :data:`MAX_TEXT`)."""
        text = _text_of(path, MAX_TEXT + 1)
        return cls(path, loaded, text if text is not None and len(text) <= MAX_TEXT else None)

    def on_reload(self, calibrations: Mapping[str, Any] | None = None) -> str | None:
        """The warning line for a SIGHUP (None: the file holds the running settings).
        ``calibrations``: the microphone calibrations the daemon runs on, by path (read once, at
        the first data: :meth:`cmsensord.monitor.microphone.Microphones.create`); one the
        configuration still names that now holds another model is not applied either."""
        try:
            now = load_config(self.path)
        except ConfigError as exc:
            error = str(exc).removeprefix(exc.source + ": ")
            if self.text is not None and _text_of(self.path, len(self.text) + 1) == self.text:
                return (f"{self.path} is unchanged since the daemon started but no longer loads: {error}; a reload "
                        "applies no setting, and a restart would stop the daemon (exit 78): put back or fix the "
                        "file it names first")
            return (f"{self.path} changed since the daemon started and does not load: {error}; a reload applies "
                    "no setting, and a restart would stop the daemon (exit 78): fix the file first")
        changes = changed_settings(config_to_dict(self.loaded), config_to_dict(now))
        edited = _edited_calibrations(now, calibrations or {})
        if not changes and not edited:
            return None
        more = f" and {len(changes) - SHOWN} more" if len(changes) > SHOWN else ""
        said = [f"{self.path} changed since the daemon started ({', '.join(changes[:SHOWN])}{more})"] if changes else []
        said += [f"the microphone calibration {', '.join(edited)} changed since the daemon read it"] if edited else []
        return (f"{'; '.join(said)}: not applied, a reload only starts a new log file; restart the daemon to apply "
                "it (systemctl restart cmsensord: alarm latches and acknowledgements are kept)")


def _edited_calibrations(cfg: Config, running: Mapping[str, Any]) -> list[str]:
    """The microphone calibration files ``cfg`` names whose model is another than the one the
    daemon runs on (``running``, by path); the MQTT files it names are not among them: the
    publisher reads them again at each connection."""
    from cmsensord.acoustic_model import load_calibration

    named = dict.fromkeys(str(ch.calibration or cfg.acoustic.calibration) for ch in cfg.channels
                          if ch.kind == "microphone")
    edited = []
    for path in (p for p in named if p in running):
        try:
            now = load_calibration(path)
        except ConfigError:             # broken since the configuration was read, a moment ago
            now = None
        if now != running[path]:
            edited.append(path)
    return edited


def _text_of(path: str, most: int = MAX_TEXT) -> bytes | None:
    """The bytes of the file at ``path``, at most ``most`` of them; None when it cannot be read."""
    try:
        with open(path, "rb") as f:
            return f.read(most)
    except (OSError, ValueError):
        return None
