"""Configuration: one YAML file -> typed, frozen dataclasses.

The file has four sections (see ``config/default.yaml``, which lists every key
with its default)::

    link:     serial port and reader settings          -> LinkConfig
    output:   MCAP directory, compression, rotation    -> OutputConfig
    monitor:  seed-000 AKF bank and anomaly decisions  -> MonitorConfig
    channels: optional list; per channel name, index, scale/offset and any
              monitor key overriding the global monitor block -> ChannelConfig

Validation is generic. Every setting is a dataclass field whose type annotation
gives the accepted type (``bool`` is not an ``int``; an ``int`` is accepted
where a ``float`` is expected) and whose ``metadata`` gives the declarative
rules (``gt``/``ge``/``lt``/``le``, ``choices``, ``pattern``, ...). Rules that
relate two fields are listed per class in ``_RULES``. The checks run in
``__post_init__``, so an object built in code is validated exactly like one
read from a file. Every failure raises :class:`~cmsensord.errors.ConfigError`
whose ``str()`` is one line naming the file, the key path and the reason.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterable, Iterator, Mapping

import yaml

from cmsensord.errors import ConfigError

__all__ = [
    "MonitorConfig",
    "ChannelConfig",
    "LinkConfig",
    "OutputConfig",
    "TachoConfig",
    "OrdersConfig",
    "ComponentConfig",
    "AcousticConfig",
    "Config",
    "MAX_CHANNELS",
    "load_config",
    "config_from_dict",
    "default_config",
    "default_channels",
    "config_to_dict",
]

#: PROTOCOL.md: STATUS carries n_channels C in 1..8.
MAX_CHANNELS = 8

_CODE = "<code>"  # source name for objects built in code rather than read from a file

# ---------------------------------------------------------------------------
# Declarative per-field rules
# ---------------------------------------------------------------------------

_RULE_KEYS = frozenset(
    {"gt", "ge", "lt", "le", "choices", "pattern", "pattern_reason", "nonzero", "nonempty"}
)


def _setting(default: Any, help: str, **rules: Any) -> Any:
    """A dataclass field carrying its help text and validation rules."""
    bad = set(rules) - _RULE_KEYS
    if bad:  # a misspelt rule must not silently disable a check
        raise TypeError(f"unknown validation rule(s) {sorted(bad)}")
    return field(default=default, metadata={"help": help, **rules})


class _Invalid(Exception):
    """Internal: a value failed a check (reason, value)."""

    def __init__(self, reason: str, value: Any) -> None:
        super().__init__(reason)
        self.reason = reason
        self.value = value


def _fmt_num(x: Any) -> str:
    return repr(x) if isinstance(x, float) else str(x)


def _coerce(tp: Any, value: Any) -> Any:
    """Check ``value`` against the annotation ``tp``; return it (int -> float)."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _coerce(inner, value)
    if origin is tuple:
        (item_tp, _ellipsis) = typing.get_args(tp)
        if not isinstance(value, (tuple, list)):
            raise _Invalid("expected a list", value)
        return tuple(_coerce(item_tp, v) for v in value)
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _Invalid("expected true or false", value)
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return int(value)
        raise _Invalid("expected an integer", value)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _Invalid("expected a number", value)
        try:
            number = float(value)
        except OverflowError:
            raise _Invalid("number too large", value) from None
        if not math.isfinite(number):
            raise _Invalid("expected a finite number", value)
        return number
    if tp is str:
        if isinstance(value, str):
            return value
        raise _Invalid("expected a string", value)
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        raise _Invalid(f"expected a {tp.__name__}", value)
    raise TypeError(f"config: unsupported annotation {tp!r}")  # programming error


def _check_rules(meta: Mapping[str, Any], value: Any) -> None:
    """Apply a field's declarative rules to its (already coerced) value."""
    if value is None:
        return
    if "choices" in meta and value not in meta["choices"]:
        reason = "must be one of " + ", ".join(str(c) for c in meta["choices"])
        near = difflib.get_close_matches(str(value), [str(c) for c in meta["choices"]], n=1)
        if near:
            reason += f" (did you mean {near[0]!r}?)"
        raise _Invalid(reason, value)
    if meta.get("nonempty") and len(value) == 0:
        raise _Invalid("must not be empty", value)
    if "pattern" in meta and not re.fullmatch(meta["pattern"], value):
        raise _Invalid(meta.get("pattern_reason") or f"must match {meta['pattern']}", value)
    if meta.get("nonzero") and value == 0:
        raise _Invalid("must not be 0", value)
    bounds = []
    ok = True
    for key, sym, test in (
        ("gt", ">", lambda v, b: v > b),
        ("ge", ">=", lambda v, b: v >= b),
        ("lt", "<", lambda v, b: v < b),
        ("le", "<=", lambda v, b: v <= b),
    ):
        if key in meta:
            bounds.append(f"{sym} {_fmt_num(meta[key])}")
            ok = ok and test(value, meta[key])
    if not ok:
        raise _Invalid("must be " + " and ".join(bounds), value)


# Cross-field rules: callables obj -> None or (key path, reason, value).
_Rule = Callable[[Any], "tuple[str, str, Any] | None"]


def _greater(key: str, other: str) -> _Rule:
    def rule(obj: Any) -> tuple[str, str, Any] | None:
        a, b = getattr(obj, key), getattr(obj, other)
        if not a > b:
            return key, f"must be greater than {other} = {_fmt_num(b)}", a
        return None

    return rule


def _at_most(key: str, other: str) -> _Rule:
    def rule(obj: Any) -> tuple[str, str, Any] | None:
        a, b = getattr(obj, key), getattr(obj, other)
        if not a <= b:
            return key, f"must be <= {other} = {_fmt_num(b)}", a
        return None

    return rule


_HINTS: dict[type, dict[str, Any]] = {}


def _validate(obj: Any) -> None:
    """Validate and normalise a config dataclass instance in place.

    Raises ConfigError(source="<code>", path=<field name>); loaders relocate it
    to the file and the full key path.
    """
    cls = type(obj)
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        value = getattr(obj, f.name)
        try:
            coerced = _coerce(hints[f.name], value)
        except _Invalid as bad:
            raise ConfigError(_CODE, f.name, bad.reason, bad.value) from None
        try:
            _check_rules(f.metadata, coerced)
        except _Invalid as bad:  # report the value as written (1, not 1.0)
            raise ConfigError(_CODE, f.name, bad.reason, value) from None
        if coerced is not value:
            object.__setattr__(obj, f.name, coerced)
    for rule in getattr(cls, "_RULES", ()):
        found = rule(obj)
        if found is not None:
            path, reason, value = found
            raise ConfigError(_CODE, path, reason, value)


# ---------------------------------------------------------------------------
# The settings
# ---------------------------------------------------------------------------


#: observations per second of board time the decision rule is written for (100 Hz RMS frames)
NOMINAL_RATE_HZ = 100.0


def _f_r_below_decision_size(obj: Any) -> tuple[str, str, Any] | None:
    per_decision = obj.decision_period_s * NOMINAL_RATE_HZ
    if not obj.f_r < per_decision:
        return "f_r", (f"must be below the {per_decision:g} observations per decision "
                       f"(decision_period_s {obj.decision_period_s:g} x {NOMINAL_RATE_HZ:g} blocks/s): "
                       "at or above it no decision can flag an anomaly"), obj.f_r
    return None


def _combined_needs_baseline(obj: Any) -> tuple[str, str, Any] | None:
    if obj.severity == "combined" and obj.baseline is None:
        return "severity", "combined needs a baseline (run `cmsensord calibrate`)", obj.severity
    return None


@dataclass(frozen=True)
class MonitorConfig:
    """Seed-000 parameters: the bank of n AKFs, outliers, 1 s anomaly decisions."""

    n: int = _setting(10, "number of AKFs in the bank (eqs. 16-18)", ge=1, le=64)
    r_min: float = _setting(4e-3, "R_min of eq. 16, smallest observation noise variance", gt=0)
    r_max: float = _setting(0.13, "R_max of eq. 16, largest observation noise variance", gt=0)
    z_c: float = _setting(2.8, "outlier critical value |z| > z_c (eq. 15); 2.8 = 99.5 %", gt=0)
    c: float = _setting(0.4, "hysteresis: an anomaly clears when cnt < c*f_r (Fig. 3)", gt=0, lt=1)
    f_r: float = _setting(28.66, "rotation frequency [Hz] compared with cnt each decision", gt=0)
    window: int = _setting(10, "N, sliding window of eqs. 11 and 14", ge=2, le=1000)
    decision_period_s: float = _setting(1.0, "seconds between anomaly decisions", gt=0)
    p0: float = _setting(1.0, "initial error variance P(0)", gt=0)
    q0: float = _setting(1e-3, "initial process noise estimate Q^(0)", ge=0)
    baseline: float | None = _setting(
        None, "healthy block RMS learned by `cmsensord calibrate`; when set the bank watches "
        "block RMS / baseline (R in units of baseline^2)", gt=0)
    baseline_spread: float | None = _setting(
        None, "robust std of the healthy per-decision level / baseline (calibrate)", ge=0)
    severity: str = _setting(
        "auto", "paper: the AKF index of Kim et al. 2023 alone; combined: also the level against "
        "the baseline (level_alert, level_danger); auto: combined when a baseline is set",
        choices=("auto", "paper", "combined"))
    level_alert: float = _setting(2.0, "level / baseline giving S_level = 0.5 (the analysts' "
                                  "2 x baseline alert)", gt=1)
    level_danger: float = _setting(4.0, "level / baseline giving S_level = 1", gt=1)

    _RULES: ClassVar[tuple[_Rule, ...]] = (_greater("r_max", "r_min"),
                                           _greater("level_danger", "level_alert"),
                                           _f_r_below_decision_size, _combined_needs_baseline)

    @property
    def combined(self) -> bool:
        """True when the severity also grades the level against the learned baseline."""
        return self.severity == "combined" or (self.severity == "auto" and self.baseline is not None)

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class ChannelConfig:
    """One measured channel: its name (MCAP topics), index and monitor settings."""

    name: str = _setting(
        dataclasses.MISSING,
        "channel name, used in the MCAP topics /cm/<name>/...",
        pattern=r"[A-Za-z0-9_]+",
        pattern_reason="must contain only letters, digits and _",
    )
    index: int = _setting(
        dataclasses.MISSING,
        "position in the RMS payload / RAW chan index",
        ge=0,
        le=MAX_CHANNELS - 1,
    )
    monitor: MonitorConfig = _setting(dataclasses.MISSING, "monitor settings of this channel")
    scale: float | None = _setting(
        None, "m/s^2 per ADC count, overriding STATUS (RAW mode)", nonzero=True
    )
    offset: float | None = _setting(None, "ADC counts at 0 m/s^2, overriding STATUS (RAW mode)")
    kind: str = _setting("accelerometer", "what the channel measures: accelerometer (m/s^2), or "
                         "microphone (Pa): its sound is turned into a vibration estimate (seed 002) "
                         "that the AKF bank watches", choices=("accelerometer", "microphone"))
    calibration: str | None = _setting(None, "acoustic calibration file of this microphone "
                                       "(default: acoustic.calibration)", nonempty=True)

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class LinkConfig:
    """The serial link to the ADC board."""

    port: str = _setting("/dev/ttyACM0", "serial device", nonempty=True)
    baud: int = _setting(921600, "UART baud rate (ignored by USB CDC and ptys)", gt=0)
    read_size: int = _setting(4096, "bytes asked for per read()", gt=0, le=16 * 1024 * 1024)
    queue_frames: int = _setting(
        4096, "bounded frame queue between reader and pipeline", ge=16, le=1_000_000
    )
    reconnect_min_s: float = _setting(0.5, "first reconnect back-off", gt=0)
    reconnect_max_s: float = _setting(5.0, "longest reconnect back-off", gt=0)
    stall_s: float = _setting(2.0, "seconds without a frame before link_stalled", gt=0)

    _RULES: ClassVar[tuple[_Rule, ...]] = (_at_most("reconnect_min_s", "reconnect_max_s"),)

    def __post_init__(self) -> None:
        _validate(self)


def _cap_holds_a_file(obj: Any) -> tuple[str, str, Any] | None:
    """OutputConfig: a retention cap below one file would delete every finished file."""
    if obj.retain_mb and obj.retain_mb < obj.rotate_mb:
        return ("retain_mb", f"must be 0 (no cap) or >= rotate_mb = {_fmt_num(obj.rotate_mb)}",
                obj.retain_mb)
    return None


@dataclass(frozen=True)
class OutputConfig:
    """Where and how the MCAP files are written."""

    dir: str = _setting("cmsensord-logs", "directory of the MCAP files", nonempty=True)
    prefix: str = _setting(
        "cmsensord",
        "file name prefix",
        pattern=r"[A-Za-z0-9_.-]+",
        pattern_reason="must contain only letters, digits, _ . and -",
    )
    compression: str = _setting(
        "zstd", "MCAP chunk compression", choices=("zstd", "lz4", "none")
    )
    flush_s: float = _setting(1.0, "seconds between chunk flushes", gt=0)
    fsync_s: float = _setting(30.0, "seconds between fsyncs", gt=0)
    rotate_s: float = _setting(3600.0, "start a new file after this many seconds", gt=0)
    rotate_mb: float = _setting(256.0, "start a new file after this many MB", gt=0)
    retain_mb: float = _setting(2048.0, "delete the oldest finished files while all files of "
                                "this prefix take more than this many MB (0: no cap)", ge=0)
    min_free_mb: float = _setting(256.0, "... and while the file system has less than this many "
                                  "MB free (0: no floor)", ge=0)
    retry_s: float = _setting(10.0, "after a disk error, try a new file this often", gt=0)
    akf_trace: bool = _setting(False, "write /cm/<ch>/akf per observation")
    akf_trace_filter: int = _setting(10, "which AKF of the bank (1..n) the trace shows", ge=1)
    status_line: bool = _setting(True, "print a one-line status to stderr")

    _RULES: ClassVar[tuple[_Rule, ...]] = (_cap_holds_a_file,)

    def __post_init__(self) -> None:
        _validate(self)


def _one_frequency(obj: Any) -> tuple[str, str, Any] | None:
    if (obj.order is None) == (obj.freq_hz is None):
        return "order", "give exactly one of order (x shaft speed) or freq_hz (fixed frequency)", obj.order
    given = [k for k in ("r", "bandwidth_hz", "bandwidth_pct") if getattr(obj, k) is not None]
    if len(given) > 1:
        return given[1], f"give at most one of r, bandwidth_hz, bandwidth_pct (also {given[0]})", \
            getattr(obj, given[1])
    return None


@dataclass(frozen=True)
class ComponentConfig:
    """One component the order tracker follows (seed 001): an order or a fixed frequency."""

    name: str = _setting(dataclasses.MISSING, "component name, e.g. 1x, whirl, whip",
                         pattern=r"[A-Za-z0-9_.]+",
                         pattern_reason="must contain only letters, digits, _ and .")
    order: float | None = _setting(None, "multiple of the shaft speed (e.g. 1, 2, 0.47)", gt=0)
    freq_hz: float | None = _setting(None, "fixed frequency [Hz] (e.g. a 47 Hz resonance)", gt=0)
    r: float | None = _setting(None, "the paper's weighting factor r (eq. 25)", gt=0)
    bandwidth_hz: float | None = _setting(None, "-3 dB bandwidth [Hz] instead of r", gt=0)
    bandwidth_pct: float | None = _setting(None, "-3 dB bandwidth in % of the component's "
                                           "frequency instead of r", gt=0, le=100)
    alarm_rms: float | None = _setting(None, "order alarm: event when the RMS rises above this "
                                       "[m/s^2] (and when it falls below alarm_clear of it)", gt=0)

    _RULES: ClassVar[tuple[_Rule, ...]] = (_one_frequency,)

    def __post_init__(self) -> None:
        _validate(self)


def _default_components() -> tuple[ComponentConfig, ...]:
    return tuple(ComponentConfig(name=f"{k}x", order=float(k)) for k in (1, 2, 3, 4))


@dataclass(frozen=True)
class OrdersConfig:
    """The recursive Vold-Kalman order tracker (seed 001) on RAW channels with a tacho."""

    enabled: bool = _setting(True, "track orders when the board sends RAW blocks and a tacho")
    q1: float = _setting(0.1, "process noise q1 of the structural equation (Q1 = q1 I, eq. 25)", gt=0)
    bandwidth_pct: float = _setting(5.0, "default -3 dB bandwidth in % of each component's "
                                    "frequency (for components without r/bandwidth)", gt=0, le=100)
    max_rpm: float = _setting(3600.0, "highest shaft speed expected: sets the tracker's "
                              "decimation and gain table", gt=0)
    min_rpm: float = _setting(300.0, "no order output below this shaft speed", gt=0)
    smoother_lag_s: float = _setting(0.0, "fixed-lag RTS smoother lag (0: the plain recursive "
                                     "filter)", ge=0, le=0.2)
    output_rate_hz: float = _setting(10.0, "order RMS/amplitude messages per second", ge=1, le=100)
    speed: str = _setting("causal", "shaft speed the tracker runs on: causal (from the edges up "
                          "to each sample, no added latency) or final (the smoothed tacho "
                          "speed, smoothing_revs + 1 pulse later)", choices=("causal", "final"))
    alarm_clear: float = _setting(0.8, "an order alarm clears below alarm_clear x alarm_rms",
                                  gt=0, lt=1)
    components: tuple[ComponentConfig, ...] = field(
        default_factory=_default_components,
        metadata={"help": "components to track (default: orders 1, 2, 3, 4)"})

    _RULES: ClassVar[tuple[_Rule, ...]] = (_greater("max_rpm", "min_rpm"),)

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class TachoConfig:
    """The shaft tacho (TACHO frames, PROTOCOL.md type 4)."""

    input: int = _setting(0, "tacho input index (TACHO chan) to use", ge=0, le=255)
    ppr: int | None = _setting(None, "pulses per revolution (default: the board's STATUS)",
                               ge=1, le=255)
    timeout_s: float = _setting(0.5, "no edge for this long -> tacho_lost event, speed invalid", gt=0)
    smoothing_revs: float = _setting(2.0, "revolutions each side of the least-squares fit that "
                                     "smooths edge jitter; the speed is final this many "
                                     "revolutions (+1 pulse) later (f_r of the decisions; the "
                                     "order latency with orders.speed: final)", gt=0, le=16)
    causal_revs: float = _setting(16.0, "revolutions behind each edge in the one-sided fit of the "
                                  "causal speed (orders.speed: causal), at most 64 pulses",
                                  gt=0, le=64)
    f_r_from_tacho: bool = _setting(True, "use the tacho speed as f_r of the anomaly decisions")

    def __post_init__(self) -> None:
        _validate(self)


@dataclass(frozen=True)
class AcousticConfig:
    """Microphone channels (kind: microphone): the seed-002 vibration estimator."""

    calibration: str | None = _setting(None, "acoustic calibration file (JSON, from "
                                       "python -m cmsensord.acoustic_calib) of the microphone "
                                       "channels without their own", nonempty=True)
    zeta_max: float = _setting(5.0, "limit of the standardised observation |z - z*| / "
                               "sqrt(Gamma_z) entering the update (noise bursts)", gt=0)

    def __post_init__(self) -> None:
        _validate(self)


def _config_rules(cfg: "Config") -> tuple[str, str, Any] | None:
    """Rules spanning sections: channel uniqueness, akf_trace_filter <= n, microphone calibration."""
    if not cfg.channels:
        return "channels", "must list at least one channel", []
    for i, ch in enumerate(cfg.channels):
        if ch.kind == "microphone" and ch.calibration is None and cfg.acoustic.calibration is None:
            return (f"channels[{i}].kind", "a microphone channel needs an acoustic calibration file "
                    f"(acoustic.calibration or channels[{i}].calibration)", ch.kind)
    seen_name: dict[str, int] = {}
    seen_index: dict[int, int] = {}
    for i, ch in enumerate(cfg.channels):
        if ch.name in seen_name:
            return (
                f"channels[{i}].name",
                f"duplicate channel name (also channels[{seen_name[ch.name]}])",
                ch.name,
            )
        if ch.index in seen_index:
            return (
                f"channels[{i}].index",
                f"duplicate channel index (also channels[{seen_index[ch.index]}])",
                ch.index,
            )
        seen_name[ch.name] = i
        seen_index[ch.index] = i
    n0 = cfg.channels[0].monitor.n
    for i, ch in enumerate(cfg.channels):
        if ch.monitor.n != n0:
            return (f"channels[{i}].n", f"every channel needs the same bank size n "
                    f"(channels[0] has {n0}): the banks run as one array", ch.monitor.n)
    k = cfg.output.akf_trace_filter
    if k > cfg.monitor.n:
        return "output.akf_trace_filter", f"must be <= monitor.n = {cfg.monitor.n}", k
    for i, ch in enumerate(cfg.channels):
        if k > ch.monitor.n:
            return (
                "output.akf_trace_filter",
                f"must be <= channels[{i}].n = {ch.monitor.n}",
                k,
            )
    return None


def default_channels(n: int, monitor: MonitorConfig | None = None) -> tuple[ChannelConfig, ...]:
    """Channels ch0..ch{n-1} with the given (or default) monitor settings."""
    mon = monitor if monitor is not None else MonitorConfig()
    return tuple(ChannelConfig(name=f"ch{i}", index=i, monitor=mon) for i in range(n))


@dataclass(frozen=True)
class Config:
    """The whole configuration. ``monitor`` is the default for every channel."""

    link: LinkConfig = field(default_factory=LinkConfig, metadata={"help": "serial link"})
    output: OutputConfig = field(default_factory=OutputConfig, metadata={"help": "MCAP output"})
    monitor: MonitorConfig = field(
        default_factory=MonitorConfig, metadata={"help": "default monitor settings"}
    )
    channels: tuple[ChannelConfig, ...] = field(
        default_factory=lambda: default_channels(1), metadata={"help": "channels"}
    )
    tacho: TachoConfig = field(default_factory=TachoConfig, metadata={"help": "shaft tacho"})
    orders: OrdersConfig = field(default_factory=OrdersConfig, metadata={"help": "order tracker"})
    acoustic: AcousticConfig = field(default_factory=AcousticConfig,
                                     metadata={"help": "microphone channels (seed 002)"})

    _RULES: ClassVar[tuple[_Rule, ...]] = (_config_rules,)

    def __post_init__(self) -> None:
        _validate(self)

    def channel(self, name: str) -> ChannelConfig:
        """The channel called ``name`` (KeyError if none)."""
        for ch in self.channels:
            if ch.name == name:
                return ch
        raise KeyError(name)


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------

_SECTIONS: dict[str, type] = {"link": LinkConfig, "output": OutputConfig, "monitor": MonitorConfig,
                              "tacho": TachoConfig, "acoustic": AcousticConfig}
_MONITOR_KEYS = tuple(f.name for f in dataclasses.fields(MonitorConfig))
_CHANNEL_OWN_KEYS = tuple(
    f.name for f in dataclasses.fields(ChannelConfig) if f.name != "monitor"
)
_CHANNEL_KEYS = _CHANNEL_OWN_KEYS + _MONITOR_KEYS
_ACOUSTIC_CHANNEL_KEYS = ("kind", "calibration")
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
        near = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        if near:
            reason += f" (did you mean {near[0]!r}?)"
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
            "top level must be a mapping with the sections link, output, monitor, channels, tacho, orders",
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

    raw_channels = d.get("channels")
    if raw_channels is None:
        channels = default_channels(n_channels or 1, monitor)
    else:
        if not isinstance(raw_channels, list):
            raise ConfigError(source, "channels", "expected a list of channel entries", raw_channels)
        built = []
        for i, entry in enumerate(raw_channels):
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
        channels = tuple(built)
    cfg = _build(Config, {**sections, "channels": channels}, source, "")
    _check_calibrations(cfg, source)
    return cfg


def _check_calibrations(cfg: Config, source: str) -> None:
    """Every microphone channel's calibration file must load (seed 002): one line naming both files."""
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


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects a key given twice in one mapping."""

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


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _StrictLoader.construct_mapping
)
# PyYAML follows YAML 1.1, where "4e-3" (no dot) is a string; accept it as a
# float, as YAML 1.2 does, since that is how the paper writes R_min.
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _yaml_reason(err: yaml.YAMLError) -> str:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or getattr(err, "context", None) or str(err)
    if mark is not None:
        return f"YAML syntax error at line {mark.line + 1}, column {mark.column + 1}: {problem}"
    return f"YAML syntax error: {problem}"


def load_config(path: str | Path | None, *, n_channels: int | None = None) -> Config:
    """Read and validate one YAML file. ``path=None`` gives the defaults.

    ``n_channels``: channel count to use when the file has no channels list.
    Every failure (missing or unreadable file, YAML syntax, unknown key, type,
    range, cross-field rule) raises ConfigError with a one-line message.
    """
    if path is None:
        return default_config(n_channels if n_channels is not None else 1)
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(source, None, "file not found") from None
    except IsADirectoryError:
        raise ConfigError(source, None, "is a directory, not a file") from None
    except PermissionError:
        raise ConfigError(source, None, "cannot read: permission denied") from None
    except UnicodeDecodeError as err:
        raise ConfigError(source, None, f"not UTF-8 text (byte offset {err.start})") from None
    except OSError as err:
        raise ConfigError(source, None, f"cannot read: {err.strerror or err}") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        raise ConfigError(source, None, _yaml_reason(err)) from None
    except RecursionError:
        raise ConfigError(source, None, "YAML nested too deeply") from None
    if data is None:  # an empty file (or only comments): all defaults
        data = {}
    return config_from_dict(data, source=source, n_channels=n_channels)


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
    }


def iter_settings(cls: type) -> Iterator[tuple[str, Any, str]]:
    """(name, default, help) of every field of a config section class."""
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else None
        yield f.name, default, f.metadata.get("help", "")
