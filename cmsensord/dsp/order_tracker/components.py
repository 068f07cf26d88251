"""Tracked components (orders of the shaft speed or fixed frequencies) and the model speed.

See docs/order_tracker.md (§1 Model, §4 Speed gate and Bandwidth).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

try:  # the compiled kernel is optional (and an older build may lack model_omega): numpy is the fallback
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None
_model_omega = getattr(_trackerkernel, "model_omega", None)

DEFAULT_R = 50.0
"""Default weighting factor.  At a 2-kHz tracker rate its -3 dB bandwidth is
15 Hz at 200 Hz, 29 Hz at 100 Hz (see :func:`r_to_bandwidth`; time constant
21 ms at 200 Hz).  The paper's r = 2000 is 0.38 Hz wide at 200 Hz here (time
constant 0.83 s): too slow for the close-orders run-up, whose ramps it then
lags by about 20 % (eq. 26)."""


@dataclass(frozen=True)
class TrackedComponent:
    """One tracked component: an order of the shaft speed or a fixed frequency.

    Exactly one of ``order`` / ``freq_hz``.  At most one of ``r`` (the paper's
    weighting factor), ``bandwidth_hz`` (the -3 dB bandwidth of the isolated
    steady-state filter, see :func:`r_to_bandwidth`) or ``bandwidth_pct`` (the
    same in % of the component's frequency, so r varies with speed); none
    means r = :data:`DEFAULT_R`.
    """

    name: str
    order: float | None = None
    freq_hz: float | None = None
    r: float | None = None
    bandwidth_hz: float | None = None
    bandwidth_pct: float | None = None

    def __post_init__(self):
        if (self.order is None) == (self.freq_hz is None):
            raise ValueError(f"component {self.name!r}: give exactly one of order, freq_hz")
        if self.order is not None and not self.order > 0:
            raise ValueError(f"component {self.name!r}: order must be > 0, got {self.order}")
        if self.freq_hz is not None and not self.freq_hz > 0:
            raise ValueError(f"component {self.name!r}: freq_hz must be > 0, got {self.freq_hz}")
        given = [k for k in ("r", "bandwidth_hz", "bandwidth_pct") if getattr(self, k) is not None]
        if len(given) > 1:
            raise ValueError(f"component {self.name!r}: give at most one of r, bandwidth_hz, "
                             f"bandwidth_pct, got {given}")
        for k in given:
            if not getattr(self, k) > 0:
                raise ValueError(f"component {self.name!r}: {k} must be > 0, got {getattr(self, k)}")

    def freq(self, rpm) -> np.ndarray:
        """Frequency [Hz] at shaft speed ``rpm``."""
        rpm = np.asarray(rpm, dtype=np.float64)
        if self.order is not None:
            return self.order * rpm / 60.0
        assert self.freq_hz is not None  # exactly one of order, freq_hz (__post_init__)
        return np.full(rpm.shape, float(self.freq_hz))


def omega(components: Sequence[TrackedComponent], speed: np.ndarray) -> np.ndarray:
    """ω_k(n) [rad/s] for model speeds ``speed`` (T,): (T, K)."""
    return np.stack([2.0 * np.pi * c.freq(speed) for c in components], axis=-1)


class Omegas:
    """:func:`omega` of ``components`` as one array operation (the same operations per entry:
    order x rpm / 60 or the fixed frequency, times 2 pi; the same values, bit for bit), for
    a tracker asking at every call."""

    def __init__(self, components: Sequence[TrackedComponent]):
        self.orders = np.array([c.order or 0.0 for c in components], dtype=np.float64)
        self.by_order = np.array([c.order is not None for c in components])
        self.all_orders = bool(self.by_order.all())
        self.fixed = np.array([2.0 * np.pi * float(c.freq_hz or 0.0) for c in components])
        self.by_order_u8 = self.by_order.astype(np.uint8)       # by_order as the kernels take it

    def __call__(self, speed: np.ndarray) -> np.ndarray:
        """ω_k(n) [rad/s] at model speeds ``speed`` (T,): (T, K)."""
        w = self.orders * speed[:, None]
        w /= 60.0
        w *= 2.0 * np.pi
        return w if self.all_orders else np.where(self.by_order, w, self.fixed)

    def scaled(self, rpm: np.ndarray, min_rpm: float, fs: float, kernel: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The model speed (T,) at speeds ``rpm`` (T,) (:func:`model_speed`) and ω / ``fs`` (T, K)
        there: in the compiled kernel when ``kernel`` and it is built (the same operations)."""
        if kernel and _model_omega is not None:
            rpm = np.ascontiguousarray(rpm, dtype=np.float64)
            speed, w = np.empty(rpm.shape[0]), np.empty((rpm.shape[0], self.orders.size))
            _model_omega(rpm, float(min_rpm), self.orders, self.fixed, self.by_order_u8, 2.0 * np.pi, float(fs),
                         speed, w)
            return speed, w
        speed = model_speed(rpm, min_rpm)
        w = self(speed)
        w /= fs
        return speed, w


def model_speed(rpm: np.ndarray, min_rpm: float) -> np.ndarray:
    """The speed the model uses: |rpm| clamped from below at min_rpm (NaN -> min_rpm)."""
    s = np.abs(np.asarray(rpm, dtype=np.float64))
    s = np.where(np.isfinite(s), s, 0.0)
    return np.maximum(s, float(min_rpm))
