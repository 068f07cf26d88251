"""The settings: one frozen dataclass per section of the configuration file.

Each field carries its default, help text and checks (:func:`~.validation.setting`);
each class validates itself on construction, so an object built in code is
checked exactly like one read from a file (:mod:`.validation`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from cmsensord.dsp.tacho.tracker import MAX_TIMEOUT_S

from .alarm_indicators import rules_see_indicators
from .alarms import AlarmsConfig, rules_levels_rise
from .capture import CaptureConfig, capture_akf_in_bank, capture_sees_operating
from .channel_refs import rules_on_bearing_channels
from .indicators import BearingConfig, IndicatorsConfig, bearings_unique
from .mqtt import MqttConfig
from .validation import Rule, at_most, fmt_num, greater, setting, validate

__all__ = [
    "MAX_CHANNELS",
    "MAX_COMPONENTS",
    "MAX_DECISION_PERIOD_S",
    "decision_period_for",
    "NOMINAL_RATE_HZ",
    "MonitorConfig",
    "ChannelConfig",
    "LinkConfig",
    "OutputConfig",
    "ComponentConfig",
    "OrdersConfig",
    "TachoConfig",
    "AcousticConfig",
    "CommissionedConfig",
    "Config",
    "default_channels",
]

#: docs/PROTOCOL.md: STATUS carries n_channels C in 1..8.
MAX_CHANNELS = 8

#: the fastest UART a USB-UART bridge offers (FT232H: 12 Mbaud); a larger baud rate is a typo
#: that the serial driver would reject only when the port opens.
MAX_BAUD = 12_000_000

#: rule of every file or device name: the OS cannot take a NUL byte in one.
_A_PATH: dict[str, Any] = {"pattern": r"[^\x00]*", "pattern_reason": "must not contain a NUL byte"}


#: observations per second of board time the decision rule is written for (100 Hz RMS frames)
NOMINAL_RATE_HZ = 100.0

#: the longest decision period [s]: an hour (the decision's buffers grow with it: 1e5 s held
#: 120 MB of one channel, 1e7 s 7.8 GB)
MAX_DECISION_PERIOD_S = 3600


def decision_period_for(f_r: float, rate_hz: float) -> int | None:
    """The shortest whole ``decision_period_s`` whose observations at ``rate_hz`` outnumber
    ``f_r`` [Hz] (a decision can flag an anomaly), or None when none up to
    :data:`MAX_DECISION_PERIOD_S` does."""
    longer = int(f_r // rate_hz) + 1
    return longer if longer <= MAX_DECISION_PERIOD_S else None


def _longer_decision(f_r: float, rate_hz: float) -> str:
    """The advice for an ``f_r`` [Hz] at or above the observations of a decision at ``rate_hz``:
    the ``decision_period_s`` that fits it, or, when none does, the highest f_r any decision takes."""
    longer = decision_period_for(f_r, rate_hz)
    if longer is None:
        return (f"no decision_period_s up to {MAX_DECISION_PERIOD_S:g} fits a machine this fast: f_r "
                f"must be below {MAX_DECISION_PERIOD_S * rate_hz:g} Hz")
    return f"for a machine this fast give decision_period_s: {longer}"


def _f_r_below_decision_size(obj: Any) -> tuple[str, str, Any] | None:
    per_decision = obj.decision_period_s * NOMINAL_RATE_HZ
    if not obj.f_r < per_decision:
        return "f_r", (f"must be below the {per_decision:g} observations per decision "
                       f"(decision_period_s {obj.decision_period_s:g} x {NOMINAL_RATE_HZ:g} blocks/s): "
                       "at or above it no decision can flag an anomaly; "
                       + _longer_decision(obj.f_r, NOMINAL_RATE_HZ)), obj.f_r
    return None


def _combined_needs_baseline(obj: Any) -> tuple[str, str, Any] | None:
    if obj.severity == "combined" and obj.baseline is None:
        return "severity", "combined needs a baseline (run `cmsensord calibrate`)", obj.severity
    return None


@dataclass(frozen=True)
class MonitorConfig:
    """Kim et al. 2023 parameters: the bank of n AKFs, outliers, 1 s anomaly decisions."""

    n: int = setting(10, "number of AKFs in the bank (eqs. 16-18)", ge=1, le=64)
    r_min: float = setting(4e-3, "R_min of eq. 16, smallest observation noise variance", gt=0)
    r_max: float = setting(0.13, "R_max of eq. 16, largest observation noise variance", gt=0)
    z_c: float = setting(2.8, "outlier critical value |z| > z_c (eq. 15); 2.8 = 99.5 %", gt=0)
    c: float = setting(0.4, "hysteresis: an anomaly clears when cnt < c*f_r (Fig. 3)", gt=0, lt=1)
    f_r: float = setting(28.66, "rotation frequency [Hz] compared with cnt each decision", gt=0)
    window: int = setting(10, "N, sliding window of eqs. 11 and 14", ge=2, le=1000)
    decision_period_s: float = setting(1.0, "seconds between anomaly decisions (at most an hour)", gt=0,
                                       le=MAX_DECISION_PERIOD_S)
    p0: float = setting(1.0, "initial error variance P(0)", gt=0)
    q0: float = setting(1e-3, "initial process noise estimate Q^(0)", ge=0)
    baseline: float | None = setting(
        None, "healthy block RMS learned by `cmsensord calibrate`; when set the bank watches "
        "block RMS / baseline (R in units of baseline^2)", gt=0)
    baseline_spread: float | None = setting(
        None, "robust std of the healthy per-decision level / baseline (calibrate)", ge=0)
    severity: str = setting(
        "auto", "paper: the AKF index of Kim et al. 2023 alone; combined: also the level against "
        "the baseline (level_alert, level_danger); auto: combined when a baseline is set",
        choices=("auto", "paper", "combined"))
    level_alert: float = setting(2.0, "level / baseline giving S_level = 0.5 (the analysts' "
                                 "2 x baseline alert)", gt=1)
    level_danger: float = setting(4.0, "level / baseline giving S_level = 1", gt=1)
    signal_floor: float = setting(0.05, "combined: a decision's level / baseline below this is no "
                                  "signal (sensor fault or machine stopped): severity and alarms held; "
                                  "0: off", ge=0, lt=1)
    flat_signal: bool = setting(True, "RAW: a block of a channel all one ADC count (a dead sensor, cut "
                                "cable or input pinned at a rail) is no observation; a decision with a "
                                "quarter of its blocks so, or a quarter all so, is no signal, with or "
                                "without a baseline: severity and alarms held")

    _RULES: ClassVar[tuple[Rule, ...]] = (greater("r_max", "r_min"),
                                          greater("level_danger", "level_alert"),
                                          _f_r_below_decision_size, _combined_needs_baseline)

    @property
    def combined(self) -> bool:
        """True when the severity also grades the level against the learned baseline."""
        return self.severity == "combined" or (self.severity == "auto" and self.baseline is not None)

    def __post_init__(self) -> None:
        validate(self)


#: the range of a channel's ``scale`` [unit per ADC count], by magnitude: a sensor's lies far inside
#: it (0.0024 m/s^2 for 1 g in 4095 counts), and (count - offset) x scale of any 16-bit count, and
#: its square, stay well inside float32, which the block RMS and the records hold
SCALE_RANGE = (1e-9, 1e6)
#: the largest ``offset`` [ADC counts] by magnitude (a 16-bit ADC counts 0..65535)
MAX_OFFSET = 1e6


def _calibration_in_range(obj: Any) -> tuple[str, str, Any] | None:
    """ChannelConfig: scale and offset within :data:`SCALE_RANGE` and :data:`MAX_OFFSET`."""
    lo, hi = SCALE_RANGE
    if obj.scale is not None and not lo <= abs(obj.scale) <= hi:
        return "scale", f"must be between {lo:g} and {hi:g} (or -{hi:g} and -{lo:g}) per ADC count", obj.scale
    if obj.offset is not None and not abs(obj.offset) <= MAX_OFFSET:
        return "offset", f"must be between -{MAX_OFFSET:g} and {MAX_OFFSET:g} ADC counts", obj.offset
    return None


#: the unit of each channel kind (ChannelConfig.unit, the simulated board's channels)
KIND_UNITS = {"accelerometer": "m/s^2", "microphone": "Pa"}


@dataclass(frozen=True)
class ChannelConfig:
    """One measured channel: its name (MCAP topics), index and monitor settings."""

    name: str = setting(
        dataclasses.MISSING,
        "channel name, used in the MCAP topics /cm/<name>/...",
        pattern=r"[A-Za-z0-9_]+",
        pattern_reason="must contain only letters, digits and _",
    )
    index: int = setting(
        dataclasses.MISSING,
        "position in the RMS payload / RAW chan index",
        ge=0,
        le=MAX_CHANNELS - 1,
    )
    monitor: MonitorConfig = setting(dataclasses.MISSING, "monitor settings of this channel")
    scale: float | None = setting(
        None, "m/s^2 per ADC count, overriding STATUS (RAW mode); 1e-9 <= |scale| <= 1e6", nonzero=True
    )
    offset: float | None = setting(None, "ADC counts at 0 m/s^2, overriding STATUS (RAW mode); "
                                   "|offset| <= 1e6")
    kind: str = setting("accelerometer", "what the channel measures: accelerometer (m/s^2), or "
                         "microphone (Pa): its sound is turned into a vibration estimate (Orimoto, Ikuta & Wang) "
                         "that the AKF bank watches", choices=("accelerometer", "microphone"))
    calibration: str | None = setting(None, "acoustic calibration file of this microphone "
                                       "(default: acoustic.calibration)", nonempty=True, **_A_PATH)
    unit: str | None = setting(None, "what the channel's values are in: m/s^2 (an accelerometer) "
                               "or Pa (a microphone); null: its kind's; one that does not fit the "
                               "kind is refused", choices=("m/s^2", "Pa"))

    _RULES: ClassVar[tuple[Rule, ...]] = (_calibration_in_range,)

    @property
    def physical_unit(self) -> str:
        """What its values are in: its kind's unit (m/s^2, a microphone's Pa)."""
        return KIND_UNITS[self.kind]

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class LinkConfig:
    """The serial link to the ADC board."""

    port: str = setting("/dev/ttyACM0", "serial device", nonempty=True, **_A_PATH)
    baud: int = setting(921600, "UART baud rate (ignored by USB CDC and ptys); at most 12 Mbaud, "
                        "the fastest USB-UART bridges", gt=0, le=MAX_BAUD)
    read_size: int = setting(4096, "bytes asked for per read()", gt=0, le=16 * 1024 * 1024)
    queue_frames: int = setting(
        4096, "bounded frame queue between reader and pipeline", ge=16, le=1_000_000
    )
    reconnect_min_s: float = setting(0.5, "first reconnect back-off", gt=0)
    reconnect_max_s: float = setting(5.0, "longest reconnect back-off", gt=0)
    stall_s: float = setting(2.0, "seconds without a frame before link_stalled", gt=0)
    reopen_s: float = setting(30.0, "seconds without a byte on an open port before it is closed and "
                              "opened again (a hung USB device); twice as long each time, up to an hour; "
                              "0: never", ge=0)
    max_drift_s: float = setting(2.0, "seconds the board's clock may run off the wall clock before "
                                 "its stamps are re-anchored (0: never, e.g. a board simulated "
                                 "faster than real time)", ge=0)

    _RULES: ClassVar[tuple[Rule, ...]] = (at_most("reconnect_min_s", "reconnect_max_s"),)

    def __post_init__(self) -> None:
        validate(self)


#: the longest output.prefix: the rest of the longest log file name
#: (``-20261130T132741Z-123456.salvaged.mcap.part.unreadable``, 54 characters) and of the alarm
#: state's temporary file fits beside it in the 255 bytes of a file name
MAX_PREFIX_LEN = 128


def _prefix_fits(obj: Any) -> tuple[str, str, Any] | None:
    """OutputConfig: a prefix that leaves room in a file name for the rest of the log's name."""
    if len(obj.prefix) > MAX_PREFIX_LEN:
        return ("prefix", f"must be at most {MAX_PREFIX_LEN} characters ({len(obj.prefix)} given): the "
                "log file names add up to 54 more, and a file name holds at most 255 bytes", obj.prefix)
    return None


def _cap_holds_a_file(obj: Any) -> tuple[str, str, Any] | None:
    """OutputConfig: a retention cap below one file would delete every finished file."""
    if obj.retain_mb and obj.retain_mb < obj.rotate_mb:
        return ("retain_mb", f"must be 0 (no cap) or >= rotate_mb = {fmt_num(obj.rotate_mb)}",
                obj.retain_mb)
    return None


@dataclass(frozen=True)
class OutputConfig:
    """Where and how the MCAP files are written."""

    dir: str = setting("cmsensord-logs", "directory of the MCAP files", nonempty=True, **_A_PATH)
    prefix: str = setting(
        "cmsensord",
        "file name prefix",
        pattern=r"[A-Za-z0-9_.-]+",
        pattern_reason="must contain only letters, digits, _ . and -",
    )
    compression: str = setting(
        "zstd", "MCAP chunk compression", choices=("zstd", "lz4", "none")
    )
    flush_s: float = setting(1.0, "seconds between chunk flushes", gt=0)
    fsync_s: float = setting(30.0, "seconds between fsyncs", gt=0)
    rotate_s: float = setting(3600.0, "start a new file after this many seconds", gt=0)
    rotate_mb: float = setting(256.0, "start a new file after this many MB", gt=0)
    retain_mb: float = setting(2048.0, "delete the oldest finished files while all files of "
                                "this prefix take more than this many MB (0: no cap)", ge=0)
    min_free_mb: float = setting(256.0, "... and while the file system has less than this many "
                                  "MB free (0: no floor)", ge=0)
    retry_s: float = setting(10.0, "after a disk error, try a new file this often", gt=0)
    akf_trace: bool = setting(False, "write /cm/<ch>/akf per observation")
    akf_trace_filter: int = setting(10, "which AKF of the bank (1..n) the trace shows", ge=1)
    status_line: bool = setting(True, "print a one-line status to stderr")

    _RULES: ClassVar[tuple[Rule, ...]] = (_prefix_fits, _cap_holds_a_file)

    def __post_init__(self) -> None:
        validate(self)


#: the least order, fixed frequency [Hz] and bandwidth [% of the frequency] of a component, and the
#: least orders.min_rpm: far below any machine's, far above the tiny numbers whose frequencies,
#: bandwidths and decimation factors overflow the tracker's design
MIN_ORDER = 0.01
MIN_FREQ_HZ = 0.01
MIN_BANDWIDTH_PCT = 0.01
MIN_RPM = 1.0
#: the least -3 dB bandwidth [Hz] of a component (a 1000-s response), and the range of the paper's
#: weighting factor r and of q1: far beyond any tracker's use, within what its design squares and
#: inverts in float64 (the gain depends on r alone: q1 scales Q1 and Q2 together)
MIN_BANDWIDTH_HZ = 0.001
R_RANGE = (1e-6, 1e12)
Q1_RANGE = (1e-12, 1e12)
#: the most components the tracker follows: its cost grows with about the cube of their count (one RAW
#: channel of 10 s at 25 kHz took 0.5 s with 32 components, 2.7 s with 64, 10 s with 100 and 62 s
#: with 200 on a 2-core machine), so 32 keep a live daemon well within real time
MAX_COMPONENTS = 32


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
    """One component the order tracker follows (Yeh, Pan & Le): an order or a fixed frequency."""

    name: str = setting(dataclasses.MISSING, "component name, e.g. 1x, whirl, whip",
                         pattern=r"[A-Za-z0-9_.]+",
                         pattern_reason="must contain only letters, digits, _ and .")
    order: float | None = setting(None, "multiple of the shaft speed (e.g. 1, 2, 0.47)", ge=MIN_ORDER)
    freq_hz: float | None = setting(None, "fixed frequency [Hz] (e.g. a 47 Hz resonance)", ge=MIN_FREQ_HZ)
    r: float | None = setting(None, "the paper's weighting factor r (eq. 25)", ge=R_RANGE[0], le=R_RANGE[1])
    bandwidth_hz: float | None = setting(None, "-3 dB bandwidth [Hz] instead of r", ge=MIN_BANDWIDTH_HZ)
    bandwidth_pct: float | None = setting(None, "-3 dB bandwidth in % of the component's "
                                           "frequency instead of r", ge=MIN_BANDWIDTH_PCT, le=100)
    alarm_rms: float | None = setting(None, "order alarm (the alarm manager's rule order_<name>): "
                                       "alert when the RMS rises above this [m/s^2]", gt=0)

    _RULES: ClassVar[tuple[Rule, ...]] = (_one_frequency,)

    def __post_init__(self) -> None:
        validate(self)


def _few_components(obj: Any) -> tuple[str, str, Any] | None:
    """OrdersConfig: at most :data:`MAX_COMPONENTS` components."""
    if len(obj.components) > MAX_COMPONENTS:
        return ("components", f"at most {MAX_COMPONENTS} components: the tracker's cost grows with about "
                "the cube of their count, and more fall behind real time",
                len(obj.components))
    return None


def _default_components() -> tuple[ComponentConfig, ...]:
    return tuple(ComponentConfig(name=f"{k}x", order=float(k)) for k in (1, 2, 3, 4))


@dataclass(frozen=True)
class OrdersConfig:
    """The recursive Vold-Kalman order tracker of Yeh, Pan & Le on RAW channels with a tacho."""

    enabled: bool = setting(True, "track orders when the board sends RAW blocks and a tacho")
    q1: float = setting(0.1, "process noise q1 of the structural equation (Q1 = q1 I, eq. 25)",
                        ge=Q1_RANGE[0], le=Q1_RANGE[1])
    bandwidth_pct: float = setting(5.0, "default -3 dB bandwidth in % of each component's "
                                    "frequency (for components without r/bandwidth)",
                                    ge=MIN_BANDWIDTH_PCT, le=100)
    max_rpm: float = setting(3600.0, "highest shaft speed expected: sets the tracker's "
                              "decimation and gain table", gt=0)
    min_rpm: float = setting(300.0, "no order output below this shaft speed", ge=MIN_RPM)
    smoother_lag_s: float = setting(0.0, "fixed-lag RTS smoother lag (0: the plain recursive "
                                     "filter)", ge=0, le=0.2)
    output_rate_hz: float = setting(10.0, "order RMS/amplitude messages per second", ge=1, le=100)
    speed: str = setting("causal", "shaft speed the tracker runs on: causal (from the edges up "
                          "to each sample, no added latency) or final (the smoothed tacho "
                          "speed, smoothing_revs + 1 pulse later)", choices=("causal", "final"))
    alarm_clear: float = setting(0.8, "an order alarm clears below alarm_clear x alarm_rms",
                                  gt=0, lt=1)
    alarm_on_delay_s: float = setting(1.0, "an order alarm needs its level exceeded this long [s]", ge=0)
    alarm_off_delay_s: float = setting(1.0, "and clears after this long below alarm_clear x alarm_rms [s]",
                                       ge=0)
    components: tuple[ComponentConfig, ...] = field(
        default_factory=_default_components,
        metadata={"help": f"components to track (default: orders 1, 2, 3, 4), at most {MAX_COMPONENTS}"})

    _RULES: ClassVar[tuple[Rule, ...]] = (greater("max_rpm", "min_rpm"), _few_components)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class TachoConfig:
    """The shaft tacho (TACHO frames, docs/PROTOCOL.md type 4)."""

    input: int = setting(0, "tacho input index (TACHO chan) to use", ge=0, le=255)
    ppr: int | None = setting(None, "pulses per revolution (default: the board's STATUS)",
                               ge=1, le=255)
    timeout_s: float = setting(0.5, "no edge for this long -> tacho_lost event, speed invalid (at most "
                               "the tracker's longest run timeout)", gt=0, le=MAX_TIMEOUT_S)
    smoothing_revs: float = setting(2.0, "revolutions each side of the least-squares fit that "
                                     "smooths edge jitter; the speed is final this many "
                                     "revolutions (+1 pulse) later (f_r of the decisions; the "
                                     "order latency with orders.speed: final)", gt=0, le=16)
    causal_revs: float = setting(16.0, "revolutions behind each edge in the one-sided fit of the "
                                  "causal speed (orders.speed: causal), at most 64 pulses",
                                  gt=0, le=64)
    f_r_from_tacho: bool = setting(True, "use the tacho speed as f_r of the anomaly decisions")

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class AcousticConfig:
    """Microphone channels (kind: microphone): the vibration estimator of Orimoto, Ikuta & Wang."""

    calibration: str | None = setting(None, "acoustic calibration file (JSON, from "
                                       "python -m cmsensord.acoustic_calib) of the microphone "
                                       "channels without their own", nonempty=True, **_A_PATH)
    zeta_max: float = setting(5.0, "limit of the standardised observation |z - z*| / "
                               "sqrt(Gamma_z) entering the update (noise bursts)", gt=0)

    def __post_init__(self) -> None:
        validate(self)


def _config_rules(cfg: Config) -> tuple[str, str, Any] | None:
    """Rules spanning sections: channel uniqueness, akf_trace_filter <= n (with akf_trace on),
    microphone calibration."""
    if not cfg.channels:
        return "channels", "must list at least one channel", []
    for i, ch in enumerate(cfg.channels):
        if ch.unit is not None and ch.unit != KIND_UNITS[ch.kind]:
            fits = next(k for k, u in KIND_UNITS.items() if u == ch.unit)
            return (f"channels[{i}].unit", f"{ch.unit} is not what a channel of kind {ch.kind} "
                    f"measures ({KIND_UNITS[ch.kind]}): set kind: {fits}", ch.unit)
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
    if not cfg.output.akf_trace:        # no trace: the setting is not used (a bank of n < 10 needs no word on it)
        return None
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


def _period_whole(obj: Any) -> tuple[str, str, Any] | None:
    """Rule: the healthy period's ``from_s`` and ``to_s`` come together, ``from_s`` before ``to_s``."""
    if (obj.from_s is None) != (obj.to_s is None):
        given, missing = ("from_s", "to_s") if obj.to_s is None else ("to_s", "from_s")
        return given, f"the healthy period needs {missing} too (its two ends, as calibrate writes them)", \
            getattr(obj, given)
    if obj.from_s is not None and not obj.from_s < obj.to_s:
        return "to_s", f"must be greater than from_s = {fmt_num(obj.from_s)}", obj.to_s
    return None


@dataclass(frozen=True)
class CommissionedConfig:
    """What ``cmsensord calibrate`` learned the baselines from (it writes this section): a
    board streaming at another sample rate or block length is warned of; a replay of the same
    capture (its real path; moved or renamed since, its size and the digest of its ends:
    :mod:`cmsensord.capture_print`) writes the healthy period [``from_s``, ``to_s``] (board
    seconds of the capture) into its log, where ``cmsensord report`` shades it."""

    capture: str | None = setting(None, "the capture the baselines were learned from (its real path)",
                                  nonempty=True)
    fs_hz: float | None = setting(None, "its board's samples per second", gt=0)
    block_len: int | None = setting(None, "its board's samples per block (one RMS value)", ge=1)
    from_s: float | None = setting(None, "the healthy period's start, board seconds of the capture", ge=0)
    to_s: float | None = setting(None, "the healthy period's end, board seconds of the capture", ge=0)
    capture_bytes: int | None = setting(None, "the capture's size [bytes], to know it again once moved", ge=0)
    capture_ends_sha256: str | None = setting(
        None, "SHA-256 of the capture's first and last 64 KiB, to know it again once moved",
        pattern=r"[0-9a-f]{64}", pattern_reason="must be 64 lowercase hex digits (as calibrate writes it)")

    _RULES: ClassVar[tuple[Rule, ...]] = (_period_whole,)

    def __post_init__(self) -> None:
        validate(self)


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
                                     metadata={"help": "microphone channels (Orimoto, Ikuta & Wang)"})
    indicators: IndicatorsConfig = field(default_factory=IndicatorsConfig,
                                         metadata={"help": "vibration indicators (ISO 10816-3, envelope)"})
    bearings: tuple[BearingConfig, ...] = field(default=(), metadata={"help": "bearings and their channels"})
    capture: CaptureConfig = field(default_factory=CaptureConfig,
                                   metadata={"help": "event-triggered captures of the signal"})
    mqtt: MqttConfig | None = field(default=None, metadata={"help": "publishing to an MQTT broker"})
    alarms: AlarmsConfig = field(default_factory=AlarmsConfig, metadata={"help": "alarm manager"})
    commissioned: CommissionedConfig = field(default_factory=CommissionedConfig,
                                             metadata={"help": "what calibrate learned the baselines from"})

    _RULES: ClassVar[tuple[Rule, ...]] = (_config_rules, bearings_unique, rules_see_indicators,
                                          rules_on_bearing_channels, rules_levels_rise, capture_sees_operating,
                                          capture_akf_in_bank)

    def __post_init__(self) -> None:
        validate(self)

    def channel(self, name: str) -> ChannelConfig:
        """The channel called ``name`` (KeyError if none)."""
        for ch in self.channels:
            if ch.name == name:
                return ch
        raise KeyError(name)

