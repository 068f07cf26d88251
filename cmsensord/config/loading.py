"""Reading a configuration: YAML file or dict -> :class:`~.settings.Config`, and back.

:func:`load_config` reads one YAML file (strict: a key given twice is an
error; ``4e-3`` is a float), :func:`config_from_dict` builds the sections,
overlays each channel's monitor keys on the global ``monitor`` block and
checks that microphone calibration files load; :func:`default_config` gives
the built-in defaults and :func:`config_to_dict` the effective settings in
the YAML shape. Every failure is one :class:`~cmsensord.errors.ConfigError`
line naming the file and the key path.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import os
import re
import stat
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from cmsensord.errors import file_kind

from .alarms import AlarmRuleConfig, AlarmsConfig, BaselineConfig, OperatingConfig, SpeedBandConfig
from .capture import CaptureConfig
from .channel_refs import check_channel_refs
from .indicators import BandConfig, BearingConfig, IndicatorsConfig
from .mqtt import MqttConfig, unreadable
from .settings import (
    MAX_CHANNELS,
    AcousticConfig,
    ChannelConfig,
    CommissionedConfig,
    ComponentConfig,
    Config,
    LinkConfig,
    MonitorConfig,
    OrdersConfig,
    OutputConfig,
    TachoConfig,
    default_channels,
)
from .validation import ConfigError, did_you_mean

_log = logging.getLogger("cmsensord")
__all__ = ["load_config", "config_from_dict", "default_config", "config_to_dict", "as_written"]

_SECTIONS: dict[str, type] = {"link": LinkConfig, "output": OutputConfig, "monitor": MonitorConfig,
                              "tacho": TachoConfig, "acoustic": AcousticConfig, "capture": CaptureConfig,
                              "commissioned": CommissionedConfig}
_MONITOR_KEYS = tuple(f.name for f in dataclasses.fields(MonitorConfig))
_CHANNEL_OWN_KEYS = tuple(
    f.name for f in dataclasses.fields(ChannelConfig) if f.name != "monitor"
)
_CHANNEL_KEYS = _CHANNEL_OWN_KEYS + _MONITOR_KEYS
_ACOUSTIC_CHANNEL_KEYS = ("kind", "calibration", "unit")
_TOP_KEYS = tuple(f.name for f in dataclasses.fields(Config))


def _join(prefix: str, key: Any) -> str:
    plain = isinstance(key, str) and re.fullmatch(r"[A-Za-z0-9_]+", key)
    key_text = key if plain else repr(key)
    return f"{prefix}.{key_text}" if prefix else key_text


def _reject_unknown(d: Mapping[Any, Any], known: Iterable[str], source: str, prefix: str) -> None:
    known = tuple(known)
    for key in d:
        if key in known:
            continue
        reason = f"unknown key {key!r}"
        hint = did_you_mean(str(key), known)
        if hint:
            reason += f" ({hint})"
        else:
            reason += f" (known keys: {', '.join(known)})"
        raise ConfigError(source, _join(prefix, key), reason)


def _mapping(value: Any, source: str, path: str) -> dict[Any, Any]:
    """A section: a mapping, or empty when the key is present with no value."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(source, path, "expected a mapping of keys to values", value)
    return value


def _build(cls: type, values: Mapping[str, Any], source: str, prefix: str) -> Any:
    """``cls(**values)``; a required key that is absent or a failed check is a ConfigError
    at ``prefix`` in ``source``."""
    for f in dataclasses.fields(cls):
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        if required and f.name not in values:
            raise ConfigError(source, _join(prefix, f.name), "missing (required)")
    try:
        return cls(**values)
    except ConfigError as err:
        raise err.relocated(source, prefix) from None


def _check_n_channels(n: Any, source: str) -> None:
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_CHANNELS:
        raise ConfigError(source, "n_channels", f"must be an integer in 1..{MAX_CHANNELS}", n)


def config_from_dict(
    d: Any, *, source: str = "<dict>", n_channels: int | None = None
) -> Config:
    """Validate a dict of the YAML shape and build a Config.

    ``n_channels``: if given and ``d`` has no channels list, make ch0..ch{n-1}
    (default 1). Raises ConfigError naming ``source`` and the key path.
    """
    if n_channels is not None:
        _check_n_channels(n_channels, source)
    if not isinstance(d, dict):
        raise ConfigError(
            source,
            None,
            f"top level must be a mapping of the sections {', '.join(_TOP_KEYS)}",
            d,
        )
    _reject_unknown(d, _TOP_KEYS, source, "")
    sections: dict[str, Any] = {}
    for name, cls in _SECTIONS.items():
        values = _mapping(d.get(name), source, name)
        _reject_unknown(values, [f.name for f in dataclasses.fields(cls)], source, name)
        sections[name] = _build(cls, values, source, name)
    monitor: MonitorConfig = sections["monitor"]
    sections["orders"] = _build_orders(d.get("orders"), source)
    sections["indicators"] = _build_indicators(d.get("indicators"), source)
    sections["bearings"] = _build_list(BearingConfig, d.get("bearings"), source, "bearings",
                                       "(name: ..., channel: ..., elements: ...)")
    sections["mqtt"] = _build_mqtt(d.get("mqtt"), source)
    sections["alarms"] = _build_alarms(d.get("alarms"), source)

    channels = _build_channels(d.get("channels"), monitor, n_channels, source)
    cfg = _build(Config, {**sections, "channels": channels}, source, "")
    if d.get("channels") is not None:           # the channels' names are known: the list's
        check_channel_refs(cfg, cfg.channels, source)
    _check_calibrations(cfg, source)
    return cfg


def _build_channels(raw: Any, monitor: MonitorConfig, n_channels: int | None,
                    source: str) -> tuple[ChannelConfig, ...]:
    """The channels list: each entry's own keys, and its monitor keys overlaid on the global
    ``monitor`` block; no list gives ch0..ch{n_channels-1} (default 1)."""
    if raw is None:
        return default_channels(n_channels or 1, monitor)
    if not isinstance(raw, list):
        raise ConfigError(source, "channels", "expected a list of channel entries", raw)
    built = []
    for i, entry in enumerate(raw):
        path = f"channels[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(source, path, "expected a mapping (name: ..., index: ...)", entry)
        _reject_unknown(entry, _CHANNEL_KEYS, source, path)
        own = {k: entry[k] for k in _CHANNEL_OWN_KEYS if k in entry}
        own.setdefault("index", i)
        if "name" not in own:
            idx = own["index"]
            own["name"] = f"ch{idx}" if isinstance(idx, int) and not isinstance(idx, bool) else f"ch{i}"
        overrides = {k: entry[k] for k in _MONITOR_KEYS if k in entry}
        try:
            ch_monitor = dataclasses.replace(monitor, **overrides) if overrides else monitor
        except ConfigError as err:
            raise err.relocated(source, path) from None
        built.append(_build(ChannelConfig, {**own, "monitor": ch_monitor}, source, path))
    return tuple(built)


def _check_calibrations(cfg: Config, source: str) -> None:
    """Every microphone channel's calibration file must load: one line naming both files."""
    for i, ch in enumerate(cfg.channels):
        if ch.kind != "microphone":
            continue
        key = f"channels[{i}].calibration" if ch.calibration is not None else "acoustic.calibration"
        from cmsensord.acoustic_model import load_calibration

        try:
            load_calibration(ch.calibration or cfg.acoustic.calibration)
        except ConfigError as err:
            raise ConfigError(source, key, str(err)) from None


def _build_orders(raw: Any, source: str) -> OrdersConfig:
    values = _mapping(raw, source, "orders")
    _reject_unknown(values, [f.name for f in dataclasses.fields(OrdersConfig)], source, "orders")
    if "components" in values:
        comps = values["components"]
        if not isinstance(comps, list) or not comps:
            raise ConfigError(source, "orders.components", "expected a non-empty list of components",
                              comps)
        built = []
        keys = [f.name for f in dataclasses.fields(ComponentConfig)]
        for i, entry in enumerate(comps):
            path = f"orders.components[{i}]"
            if not isinstance(entry, dict):
                raise ConfigError(source, path, "expected a mapping (name: ..., order: ...)", entry)
            _reject_unknown(entry, keys, source, path)
            built.append(_build(ComponentConfig, entry, source, path))
        names = [c.name for c in built]
        dup = next((n for n in names if names.count(n) > 1), None)
        if dup is not None:
            raise ConfigError(source, f"orders.components[{names.index(dup, names.index(dup) + 1)}].name",
                              "duplicate component name", dup)
        values = {**values, "components": tuple(built)}
    return _build(OrdersConfig, values, source, "orders")


def _build_list(cls: type, raw: Any, source: str, path: str, shape: str) -> tuple:
    """A list of ``cls`` entries (absent or empty: none)."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise ConfigError(source, path, f"expected a list of entries {shape}", raw)
    keys = [f.name for f in dataclasses.fields(cls)]
    built = []
    for i, entry in enumerate(raw):
        where = f"{path}[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(source, where, f"expected a mapping {shape}", entry)
        _reject_unknown(entry, keys, source, where)
        built.append(_build(cls, entry, source, where))
    return tuple(built)


def _build_indicators(raw: Any, source: str) -> IndicatorsConfig:
    values = _mapping(raw, source, "indicators")
    _reject_unknown(values, [f.name for f in dataclasses.fields(IndicatorsConfig)], source, "indicators")
    if "bands" in values:
        values = {**values, "bands": _build_list(BandConfig, values["bands"], source, "indicators.bands",
                                                 "(name: ..., lo_hz: ..., hi_hz: ...)")}
    return _build(IndicatorsConfig, values, source, "indicators")


def _build_mqtt(raw: Any, source: str) -> MqttConfig | None:
    """The optional ``mqtt`` section; its files must be readable, its TLS files must hold what
    they are for (:func:`~.mqtt_tls.tls_context`), and paho-mqtt must be installed.

    A file under ``/run/credentials/`` that is missing outside systemd (no ``INVOCATION_ID``:
    ``replay``, ``status``, ``ack`` run by hand with the service's configuration) is a service
    credential, there only while the unit runs: one warning line, not checked, and a command
    that publishes then fails to connect with it."""
    if raw is None:
        return None
    values = _mapping(raw, source, "mqtt")
    _reject_unknown(values, [f.name for f in dataclasses.fields(MqttConfig)], source, "mqtt")
    cfg: MqttConfig = _build(MqttConfig, values, source, "mqtt")
    absent = []
    for key in ("password_file", "ca_file", "certfile", "keyfile"):
        path = getattr(cfg, key)
        if path is not None:
            try:
                with open(path, "rb"):
                    pass
            except OSError as err:
                if not _service_credential(path, err):
                    raise ConfigError(source, f"mqtt.{key}", unreadable(key, path, err), path) from None
                absent.append(key)
    if absent:
        _log.warning("config: %s: not checked: the service's credential(s), there only while the unit runs",
                     ", ".join(f"mqtt.{key} {getattr(cfg, key)}" for key in absent))
    from .mqtt_tls import TlsFileError, tls_context  # ssl only with an mqtt section (2 MB of RSS)

    try:
        if not set(absent) - {"password_file"}:     # a TLS file not there: its context is the service's
            tls_context(cfg)
    except TlsFileError as err:
        raise ConfigError(source, f"mqtt.{err.key}", f"{err.path}: {err.reason}") from None
    import importlib.util

    if importlib.util.find_spec("paho") is None or importlib.util.find_spec("paho.mqtt") is None:
        raise ConfigError(source, "mqtt", "publishing needs paho-mqtt: pip install 'cmsensord[mqtt]'")
    return cfg


def _service_credential(path: str, err: OSError) -> bool:
    """A missing file under ``/run/credentials/`` read outside systemd."""
    return (err.errno == errno.ENOENT and path.startswith("/run/credentials/")
            and "INVOCATION_ID" not in os.environ)


def _build_alarms(raw: Any, source: str) -> AlarmsConfig:
    values = dict(_mapping(raw, source, "alarms"))
    _reject_unknown(values, [f.name for f in dataclasses.fields(AlarmsConfig)], source, "alarms")
    op = _mapping(values.get("operating"), source, "alarms.operating")
    _reject_unknown(op, [f.name for f in dataclasses.fields(OperatingConfig)], source, "alarms.operating")
    values["operating"] = _build(OperatingConfig, op, source, "alarms.operating")
    rules = values.get("rules")
    if isinstance(rules, list):
        rules = [{**r, "bands": _build_list(SpeedBandConfig, r["bands"], source, f"alarms.rules[{i}].bands",
                                            "(below_rpm: ..., alert: ..., danger: ...)")}
                 if isinstance(r, dict) and "bands" in r else r for i, r in enumerate(rules)]
    values["rules"] = _build_list(AlarmRuleConfig, rules, source, "alarms.rules",
                                  "(name: ..., indicator: ..., alert: ..., danger: ...)")
    values["baselines"] = _build_list(BaselineConfig, values.get("baselines"), source, "alarms.baselines",
                                      "(channel: ..., indicator: ..., value: ...)")
    return _build(AlarmsConfig, values, source, "alarms")


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects a key given twice in one mapping."""

    def get_single_node(self) -> Any:
        """The document's node graph, refused before construction if its aliases expand too far."""
        node = super().get_single_node()
        if node is not None:
            _expanded_nodes(node)
        return node

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _value_node in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:  # unhashable key: SafeLoader reports it below
                    continue
                if duplicate:
                    raise yaml.constructor.ConstructorError(
                        "while constructing a mapping",
                        node.start_mark,
                        f"found duplicate key {key!r}",
                        key_node.start_mark,
                    )
        return super().construct_mapping(node, deep=deep)

    def construct_object(self, node: Any, deep: bool = False) -> Any:
        """A node's value; a scalar Python cannot make one of (a whole number of more than
        4,300 digits, a date with month 13, an empty ``!!int``) is refused with its place in the
        file (:func:`_unmade`)."""
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, OverflowError, IndexError, KeyError, AttributeError, TypeError) as err:
            if not isinstance(node, yaml.ScalarNode):
                raise
            mark = node.start_mark
            raise _TooLarge(f"line {mark.line + 1}, column {mark.column + 1}: {_unmade(node, err)}") from None


def _unmade(node: yaml.ScalarNode, err: Exception) -> str:
    """Why the scalar ``node`` (its tag, as written or resolved) makes no value: a whole number
    past the digits Python converts, or the value is not what its tag says."""
    value, kind = str(node.value), node.tag.rpartition(":")[2]
    shown = repr(value if len(value) <= 40 else value[:37] + "...")
    if kind == "int" and value.lstrip("+-").replace("_", "").isdigit():
        return f"number too large (a whole number of {len(value):,} characters)"
    if kind == "timestamp" and isinstance(err, ValueError) and str(err):
        return f"not a date ({err})"
    what = {"int": "a whole number", "float": "a number", "timestamp": "a date", "bool": "true or false"}
    return f"not {what.get(kind, f'a YAML {kind}')} ({shown})"


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _StrictLoader.construct_mapping
)
# PyYAML follows YAML 1.1, where an exponent needs a dot and a sign: "4e-3" and "1.0e300"
# are strings there. Accept every exponent form as a float, as YAML 1.2 does ("4e-3" is
# how the paper writes R_min).
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


#: the largest configuration file read: the defaults with comments are ~10 kB
MAX_CONFIG_BYTES = 1 << 20
#: the most YAML nodes a document may stand for once every alias is expanded
MAX_YAML_NODES = 100_000


def _read_text(path: str | Path, source: str) -> str:
    """The text of a regular file of at most MAX_CONFIG_BYTES; anything else is a ConfigError.

    The file is opened non-blocking, so a FIFO never waits for a writer, and its type is
    checked on the open descriptor before anything is read (a device such as /dev/zero
    is refused, not read to the end of memory).
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(source, None, "file not found (`cmsensord config --default > FILE` writes one with every "
                          "setting)") from None
    except PermissionError:
        raise ConfigError(source, None, "cannot read: permission denied") from None
    except OSError as err:
        raise ConfigError(source, None, f"cannot read: {err.strerror or err}") from None
    except ValueError as err:  # a name the OS cannot take (a NUL byte, shown escaped)
        reason = "not a usable file name: it contains a NUL byte" if "\0" in source else f"cannot read: {err}"
        raise ConfigError(source.replace("\0", "\\0"), None, reason) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise ConfigError(source, None, "is a directory, not a file")
        raise ConfigError(source, None, f"not a regular file (a {file_kind(mode)}); "
                          "give the path of a YAML file")
    with os.fdopen(fd, "rb") as f:
        try:
            data = f.read(MAX_CONFIG_BYTES + 1)
        except OSError as err:
            raise ConfigError(source, None, f"cannot read: {err.strerror or err}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(source, None, f"larger than {MAX_CONFIG_BYTES} bytes: not a configuration file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(source, None, _not_text(source, data, err.start)) from None


def _not_text(source: str, data: bytes, start: int) -> str:
    """Why the configuration file ``source`` (its bytes ``data``) is no text: an MCAP log or a
    capture given as the configuration, with what reads it, or the first byte that is not UTF-8."""
    from cmsensord.sinks.mcap_chunks import MAGIC
    from cmsensord.sinks.mcap_records import is_capture

    site = "--config takes a YAML site file (`cmsensord config --default > site.yaml` writes one)"
    if data.startswith(MAGIC):
        return (f"an MCAP log (cmsensord's output), not a configuration: `cmsensord summary` and "
                f"`cmsensord report` read it; {site}")
    if is_capture(source):
        return (f"a capture of the board's serial stream, not a configuration: replay, calibrate and vkf read "
                f"it (`cmsensord replay {source} --config site.yaml`); {site}")
    return f"not UTF-8 text (byte offset {start})"


class _TooLarge(Exception):
    """Internal: the YAML document stands for too many nodes (aliases), or refers to itself,
    or holds a value Python cannot make (a whole number past 4,300 digits, an impossible date)."""


def _expanded_nodes(root: yaml.Node) -> int:
    """How many nodes ``root`` stands for with every alias expanded (shared nodes counted each
    time they are referred to), computed without expanding; raises _TooLarge past
    MAX_YAML_NODES or when a node contains itself."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in open_nodes:
            raise _TooLarge("a YAML alias refers to a node that contains it (a recursive structure)")
        total = 1
        if isinstance(node, (yaml.SequenceNode, yaml.MappingNode)):
            open_nodes.add(key)
            children = (node.value if isinstance(node, yaml.SequenceNode)
                        else [n for pair in node.value for n in pair])
            for child in children:
                total += size(child)
                if total > MAX_YAML_NODES:
                    raise _TooLarge(f"YAML aliases expand to more than {MAX_YAML_NODES} values")
            open_nodes.discard(key)
        sizes[key] = total
        return total

    return size(root)


def _yaml_reason(err: yaml.YAMLError) -> str:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or getattr(err, "context", None) or str(err)
    if "'\\t'" in problem:
        problem += ": indent with spaces, not tabs"
    if mark is not None:
        return f"YAML syntax error at line {mark.line + 1}, column {mark.column + 1}: {problem}"
    return f"YAML syntax error: {problem}"


def load_config(path: str | Path | None, *, n_channels: int | None = None) -> Config:
    """Read and validate one YAML file. ``path=None`` gives the defaults.

    ``n_channels``: channel count to use when the file has no channels list.
    Every failure (missing or unreadable file, YAML syntax, unknown key, type,
    range, cross-field rule) raises ConfigError with a one-line message; a file
    holding no settings (empty, or comments only) is logged in one warning line.
    """
    if path is None:
        return default_config(n_channels if n_channels is not None else 1)
    source = str(path)
    text = _read_text(path, source)
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        raise ConfigError(source, None, _yaml_reason(err)) from None
    except RecursionError:
        raise ConfigError(source, None, "YAML nested too deeply") from None
    except _TooLarge as err:
        raise ConfigError(source, None, str(err)) from None
    if data is None:  # an empty file (or only comments): all defaults
        data = {}
    cfg = config_from_dict(data, source=source, n_channels=n_channels)
    if data == {}:      # a site file emptied by mistake would run without its calibration: say so
        _log.warning("config: %s holds no settings (empty, or comments only): every setting is its default",
                     source)
    return cfg


def as_written(path: str | Path | None) -> dict[str, Any]:
    """The top-level mapping of the configuration file ``path`` as written, before defaults (what
    it sets itself); {} without a file, or for one that is not a YAML mapping (:func:`load_config`
    says why)."""
    if path is None:
        return {}
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError, yaml.YAMLError):
        return {}
    return data if isinstance(data, dict) else {}


def default_config(n_channels: int = 1) -> Config:
    """The built-in defaults with channels ch0..ch{n_channels-1}."""
    _check_n_channels(n_channels, "<default>")
    return Config(channels=default_channels(n_channels))


def config_to_dict(cfg: Config) -> dict[str, Any]:
    """The effective settings as a plain dict of the YAML shape (for logging).

    Channel entries list name, index, scale, offset and only the monitor keys
    that differ from the global monitor block, so
    ``config_from_dict(config_to_dict(cfg)) == cfg``.
    """
    glob = dataclasses.asdict(cfg.monitor)
    channels = []
    for ch in cfg.channels:
        entry: dict[str, Any] = {k: getattr(ch, k) for k in _CHANNEL_OWN_KEYS
                                 if k not in _ACOUSTIC_CHANNEL_KEYS}
        if ch.kind != "accelerometer":          # listed only for microphone channels
            entry.update(kind=ch.kind, calibration=ch.calibration)
        if ch.unit is not None:
            entry["unit"] = ch.unit
        mon = dataclasses.asdict(ch.monitor)
        entry.update({k: v for k, v in mon.items() if glob[k] != v})
        channels.append(entry)
    return {
        "link": dataclasses.asdict(cfg.link),
        "output": dataclasses.asdict(cfg.output),
        "monitor": glob,
        "channels": channels,
        "tacho": dataclasses.asdict(cfg.tacho),
        "orders": {**dataclasses.asdict(cfg.orders),
                   "components": [{k: v for k, v in dataclasses.asdict(c).items() if v is not None}
                                  for c in cfg.orders.components]},
        "acoustic": dataclasses.asdict(cfg.acoustic),
        "indicators": {**dataclasses.asdict(cfg.indicators),
                       "velocity_band_hz": _as_list(cfg.indicators.velocity_band_hz),
                       "envelope_band_hz": _as_list(cfg.indicators.envelope_band_hz),
                       "bands": [{k: v for k, v in dataclasses.asdict(b).items() if v is not None}
                                 for b in cfg.indicators.bands]},
        "bearings": [dataclasses.asdict(b) for b in cfg.bearings],
        "capture": {**dataclasses.asdict(cfg.capture), "triggers": list(cfg.capture.triggers)},
        **({"mqtt": {**dataclasses.asdict(cfg.mqtt), "publish": list(cfg.mqtt.publish)}}
           if cfg.mqtt is not None else {}),
        "alarms": _alarms_dict(cfg.alarms),
        "commissioned": dataclasses.asdict(cfg.commissioned),
    }


def _alarms_dict(a: AlarmsConfig) -> dict:
    def rule(r: AlarmRuleConfig) -> dict:
        d = {k: v for k, v in dataclasses.asdict(r).items() if v is not None and k != "bands"}
        d["channels"] = list(r.channels)
        if r.bands:
            d["bands"] = [{k: v for k, v in dataclasses.asdict(b).items() if v is not None} for b in r.bands]
        return d
    return {"enabled": a.enabled, "operating": dataclasses.asdict(a.operating),
            "rules": [rule(r) for r in a.rules], "baselines": [dataclasses.asdict(b) for b in a.baselines]}


def _as_list(v: tuple | None) -> list | None:
    return None if v is None else list(v)
