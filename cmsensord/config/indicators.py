"""Settings of the vibration indicators (``indicators``) and the bearings they watch (``bearings``).

:class:`IndicatorsConfig` sets the interval, the ISO 10816-3 machine class, the
velocity and envelope bands and the band RMS list; each :class:`BearingConfig`
names a bearing, its geometry and the channel whose accelerometer sees it.  The
computation is :mod:`cmsensord.dsp.indicators`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .validation import Rule, fmt_num, greater, setting, validate

__all__ = ["BandConfig", "IndicatorsConfig", "BearingConfig", "bearings_unique", "zones_assumed"]

_NAME: dict[str, Any] = {"pattern": r"[A-Za-z0-9_.]+", "pattern_reason": "must contain only letters, digits, _ and ."}


def _edges(key: str) -> Rule:
    """Rule: the optional field ``key`` is two numbers lo < hi, lo >= 0."""

    def rule(obj: Any) -> tuple[str, str, Any] | None:
        v = getattr(obj, key)
        if v is not None and not (len(v) == 2 and 0 <= v[0] < v[1]):
            return key, "must be two frequencies [lo, hi] in Hz with 0 <= lo < hi", list(v)
        return None

    return rule


def _one_kind(obj: Any) -> tuple[str, str, Any] | None:
    hz = (obj.lo_hz, obj.hi_hz)
    orders = (obj.lo_order, obj.hi_order)
    in_hz = hz != (None, None)
    if in_hz == (orders != (None, None)):
        return "lo_hz", "give either lo_hz and hi_hz, or lo_order and hi_order", obj.lo_hz
    lo, hi, key = (*hz, "hi_hz") if in_hz else (*orders, "hi_order")
    if None in (lo, hi):
        return key, "give both ends of the band", hi
    if not hi > lo:
        return key, f"must be greater than {key.replace('hi', 'lo')} = {fmt_num(lo)}", hi
    return None


@dataclass(frozen=True)
class BandConfig:
    """One band of the band RMS: in Hz, or in orders of the shaft speed."""

    name: str = setting(dataclasses.MISSING, "band name (in /cm/<ch>/indicators bands[])", **_NAME)
    lo_hz: float | None = setting(None, "lower edge [Hz]", ge=0)
    hi_hz: float | None = setting(None, "upper edge [Hz]", gt=0)
    lo_order: float | None = setting(None, "lower edge [orders of the shaft speed]", ge=0)
    hi_order: float | None = setting(None, "upper edge [orders of the shaft speed]", gt=0)

    _RULES: ClassVar[tuple[Rule, ...]] = (_one_kind,)

    def __post_init__(self) -> None:
        validate(self)


def _unique_bands(obj: Any) -> tuple[str, str, Any] | None:
    names = [b.name for b in obj.bands]
    for i, n in enumerate(names):
        if n in names[:i]:
            return f"bands[{i}].name", "duplicate band name", n
    return None


@dataclass(frozen=True)
class IndicatorsConfig:
    """Vibration indicators per channel and interval (RAW mode; RMS mode: the overall RMS only)."""

    enabled: bool = setting(True, "write /cm/<channel>/indicators")
    interval_s: float = setting(1.0, "seconds of board time per indicator record", gt=0, le=60)
    machine_group: int = setting(2, "ISO 10816-3 machine group: 1 (> 300 kW) or 2 (15-300 kW)", ge=1, le=2)
    foundation: str = setting("rigid", "ISO 10816-3 foundation", choices=("rigid", "flexible"))
    rpm: float | None = setting(None, "shaft speed [rpm] when there is no tacho or it gives no speed "
                                "(bearing frequencies, order bands, the velocity band)", gt=0)
    velocity_band_hz: tuple[float, ...] | None = setting(
        None, "[lo, hi] Hz of the velocity RMS (default: by the record's speed, 2-1000 at or below "
        "600 rpm, else 10-1000)")
    envelope_band_hz: tuple[float, ...] | None = setting(
        None, "[lo, hi] Hz demodulated (default: 0.08-0.4 fs, 2-10 kHz at 25 kHz)")
    max_missing_fraction: float = setting(
        0.05, "share of a record's samples that may be missing (lost frames) with its spectral "
        "indicators still given, from the samples it has; 0: only from complete records", ge=0, le=0.5)
    slip_pct: float = setting(2.0, "search window +/- % around each defect frequency", ge=0, le=10)
    velocity_baseline_mm_s: float | None = setting(
        None, "healthy velocity RMS [mm/s]: the ISO alarm level is baseline + 0.25 x B/C "
        "(at most 1.25 x B/C)", gt=0)
    bands: tuple[BandConfig, ...] = field(default=(), metadata={"help": "band RMS list"})

    _RULES: ClassVar[tuple[Rule, ...]] = (_edges("velocity_band_hz"), _edges("envelope_band_hz"),
                                          _unique_bands)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class BearingConfig:
    """A rolling-element bearing, its geometry and the channel whose accelerometer sees it."""

    name: str = setting(dataclasses.MISSING, "bearing name, e.g. motor_de", **_NAME)
    channel: str = setting(dataclasses.MISSING, "name of the channel that sees it",
                           pattern=r"[A-Za-z0-9_]+", pattern_reason="must contain only letters, digits and _")
    elements: int = setting(dataclasses.MISSING, "number of rolling elements", ge=1, le=200)
    ball_diameter: float = setting(dataclasses.MISSING, "rolling element diameter (any unit, as pitch_diameter)", gt=0)
    pitch_diameter: float = setting(dataclasses.MISSING, "pitch diameter (same unit)", gt=0)
    contact_angle_deg: float = setting(0.0, "contact angle [degrees]", ge=0, lt=90)

    _RULES: ClassVar[tuple[Rule, ...]] = (greater("pitch_diameter", "ball_diameter"),)

    def __post_init__(self) -> None:
        validate(self)


def bearings_unique(cfg: Any) -> tuple[str, str, Any] | None:
    """Config rule: bearing names are unique (the channel each names is checked against the
    channels' names once they are known: :mod:`.channel_refs`)."""
    seen: list[str] = []
    for i, b in enumerate(cfg.bearings):
        if b.name in seen:
            return f"bearings[{i}].name", "duplicate bearing name", b.name
        seen.append(b.name)
    return None


def zones_assumed(ind: IndicatorsConfig, given: Any) -> str | None:
    """The note that the ISO 10816-3 zones are graded for a machine class the configuration
    does not set (``given``: its ``indicators`` mapping as written, None without one): which
    group and foundation are assumed, their boundaries, and the keys that set them; None when
    both are set or no indicator record is written."""
    from cmsensord.dsp.indicators.iso_zones import boundaries

    keys = given if isinstance(given, dict) else {}
    unset = [k for k in ("machine_group", "foundation") if k not in keys]
    if not ind.enabled or not unset:
        return None
    size = "> 300 kW" if ind.machine_group == 1 else "15-300 kW"
    edges = "/".join(f"{b:g}" for b in boundaries(ind.machine_group, ind.foundation))
    return (f"note: ISO 10816-3 zones graded for machine group {ind.machine_group} ({size}) on a "
            f"{ind.foundation} foundation ({edges} mm/s), {' and '.join(unset)} not set: the standard covers "
            "machines above 15 kW; set indicators.machine_group (1: > 300 kW, 2: 15-300 kW) and "
            "indicators.foundation (rigid, flexible) for this machine")
