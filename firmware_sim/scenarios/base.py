"""The base of every simulated machine: :class:`Scenario`, its segments, caches and shaft angle.

Determinism and chunk invariance
--------------------------------
Samples are generated in fixed 1-s segments (``fs`` samples). Every random
draw of segment k comes from a generator seeded with
``np.random.SeedSequence([seed, stream, k])`` where ``stream`` is the channel
index for what one sensor sees on its own (its noise) and
:data:`~firmware_sim.scenarios.noise.MACHINE_STREAM` for what the machine does
(wander of the rotation components, bearing impacts, spike positions), which
all channels share (:mod:`firmware_sim.scenarios.noise`). Whatever reaches
across a segment boundary (the ringing of a resonance, an impact jittered over
the boundary, the smooth wander) is recomputed from the neighbouring segments'
draws, never carried as state, so the samples of a range depend only on
(parameters, seed, channel) and never on how a caller chunks its requests.
The last segments are cached, so sequential reading renders each segment once.
"""

from __future__ import annotations

import abc
import inspect
import math
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from .noise import SlotDraws

__all__ = ["Scenario", "ConstantSpeed", "DEFAULT_CHANNEL_GAINS", "MAX_CHANNELS", "FULL_SCALE_MS2", "keyword_params"]

#: Sensor gains of channels 0..3 (cycled for more channels): each channel is
#: the same machine seen by a sensor with its own gain and its own noise.
DEFAULT_CHANNEL_GAINS = (1.0, 0.8, 1.2, 0.9)
MAX_CHANNELS = 8  # docs/PROTOCOL.md, STATUS: n_channels 1..8
#: accelerometer range of the simulated board: +-20 g (196 m/s^2) over the 12-bit
#: ADC, 0.096 m/s^2 per count. Bearing impacts of the faulty scenarios peak
#: near 100 m/s^2; a +-5 g range would clip them.
FULL_SCALE_MS2 = 20 * 9.80665

# shaft angle quadrature (Scenario.shaft_turns): 8-node Gauss-Legendre on 10-ms panels,
# nodes mapped to [0, 1] and weights summing to 1
_TURN_PANEL = 0.01
_PANELS_PER_S = 100
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W

_SEGMENT_CACHE = 3  # rendered segments kept (current, previous, one spare)
_DRAW_CACHE = 6  # per-segment machine draws kept (k-1, k, k+1 and spares)


class Scenario(abc.ABC):
    """A machine seen by ``n_channels`` sensors, sampled at ``fs``.

    Subclasses implement :meth:`_render` (one 1-s segment, all channels),
    :meth:`shaft_hz` and :meth:`severity`. ``duration_s`` is the length the
    scenario is designed for (the time axis of ``degrading``); samples exist
    for every index >= 0.
    """

    name: str = "scenario"
    description: str = ""

    def __init__(self, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                 fs: int = 25000, channel_gains: tuple[float, ...] | None = None):
        if not isinstance(n_channels, (int, np.integer)) or not 1 <= n_channels <= MAX_CHANNELS:
            raise ValueError(f"n_channels must be an integer 1..{MAX_CHANNELS}, got {n_channels!r}")
        if not duration_s > 0 or not math.isfinite(duration_s):
            raise ValueError(f"duration_s must be a positive number of seconds, got {duration_s!r}")
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        if not isinstance(fs, (int, np.integer)) or fs <= 0:
            raise ValueError(f"fs must be a positive integer, got {fs!r}")
        self.n_channels = int(n_channels)
        self.duration_s = float(duration_s)
        self.seed = int(seed)
        self.fs = int(fs)
        self.segment_len = self.fs  # 1-s segments
        if channel_gains is None:
            channel_gains = DEFAULT_CHANNEL_GAINS
        gains = tuple(float(g) for g in channel_gains)
        if not gains:
            raise ValueError("channel_gains must hold at least one gain")
        self.channel_gains = np.array([gains[c % len(gains)] for c in range(self.n_channels)])
        self._segments: OrderedDict[int, np.ndarray] = OrderedDict()
        self._draws = SlotDraws(self.seed, _DRAW_CACHE)
        self._turns_cum = np.zeros(1)  # shaft angle at whole seconds (shaft_turns)

    # -- public API -----------------------------------------------------------
    def samples(self, start: int, n: int) -> np.ndarray:
        """Acceleration [m/s^2], shape (n_channels, n), sample indices [start, start + n)."""
        start, n = int(start), int(n)
        if start < 0 or n < 0:
            raise ValueError(f"start and n must be >= 0, got start={start}, n={n}")
        L = self.segment_len
        out = np.empty((self.n_channels, n), dtype=np.float64)
        pos = 0
        while pos < n:
            k, off = divmod(start + pos, L)
            take = min(L - off, n - pos)
            out[:, pos:pos + take] = self._segment(k)[:, off:off + take]
            pos += take
        return out

    @abc.abstractmethod
    def shaft_hz(self, t: np.ndarray) -> np.ndarray:
        """Instantaneous shaft rotation frequency [Hz] at times t [s]."""

    def shaft_turns(self, t: np.ndarray) -> np.ndarray:
        """Shaft angle in revolutions since t = 0 (the integral of :meth:`shaft_hz`).

        Generic version: 8-node Gauss-Legendre quadrature on 10-ms panels (exact
        for speed profiles that are polynomials of degree <= 15 within a panel).
        The angle at whole seconds is cached and extended by sequential sums,
        so a value never depends on the order of the requests. Constant-speed
        scenarios override this with the exact product.
        """
        t = np.asarray(t, dtype=np.float64)
        flat = t.ravel()
        if flat.size == 0:
            return np.zeros(t.shape)
        if not flat.min() >= 0:
            raise ValueError("shaft_turns needs t >= 0")
        sec = np.floor(flat).astype(np.int64)
        at_s = self._turns_at_seconds(int(sec.max()))
        useconds, ui = np.unique(sec, return_inverse=True)
        panels = self._panel_turns(useconds)  # (U, panels per second)
        pc = np.concatenate([np.zeros((useconds.size, 1)), np.cumsum(panels, axis=1)], axis=1)
        p = np.minimum(np.floor((flat - sec) / _TURN_PANEL).astype(np.int64), _PANELS_PER_S - 1)
        a = sec + p * _TURN_PANEL
        width = flat - a
        tq = a[:, None] + width[:, None] * _GL_X[None, :]
        partial = width * (self.shaft_hz(tq) @ _GL_W)
        return (at_s[sec] + pc[ui.ravel(), p] + partial).reshape(t.shape)

    def _panel_turns(self, seconds: np.ndarray) -> np.ndarray:
        """Revolutions in each 10-ms panel of the given whole seconds, shape (len, 100)."""
        a = seconds[:, None] + np.arange(_PANELS_PER_S)[None, :] * _TURN_PANEL
        tq = a[..., None] + _TURN_PANEL * _GL_X
        return _TURN_PANEL * (self.shaft_hz(tq) @ _GL_W)

    def _turns_at_seconds(self, last: int) -> np.ndarray:
        """Cached shaft angle at t = 0, 1, ..., >= last seconds."""
        cum = self._turns_cum
        while cum.size <= last:
            new = np.arange(cum.size - 1, min(last + 1, cum.size - 1 + 3600))
            per_s = self._panel_turns(new).sum(axis=1)
            cum = np.concatenate([cum[:-1], np.cumsum(np.concatenate([cum[-1:], per_s]))])
        self._turns_cum = cum
        return cum

    @abc.abstractmethod
    def severity(self, t) -> np.ndarray:
        """The scenario's fault-severity knob s(t) (0 = healthy) at times t [s]."""

    @property
    def params(self) -> dict[str, Any]:
        """The effective constructor parameters (for logs and the CLI)."""
        out = {}
        for cls in type(self).__mro__:
            init = cls.__dict__.get("__init__")
            if init is None:
                continue
            for p in inspect.signature(init).parameters.values():
                if p.kind is not p.KEYWORD_ONLY or p.name in out:
                    continue
                v = getattr(self, p.name, None)
                if callable(v):  # shaft_hz is a method; its value is kept as shaft_hz_value
                    v = getattr(self, p.name + "_value", None)
                if v is not None:
                    out[p.name] = v.tolist() if isinstance(v, np.ndarray) else v
        return out

    # -- machinery -------------------------------------------------------------
    def _segment(self, k: int) -> np.ndarray:
        seg = self._segments.get(k)
        if seg is None:
            seg = self._render(k)
            seg.flags.writeable = False
            self._segments[k] = seg
            while len(self._segments) > _SEGMENT_CACHE:
                self._segments.popitem(last=False)
        else:
            self._segments.move_to_end(k)
        return seg

    def _cached_draw(self, stream: int, k: int, make: Callable[[np.random.Generator, int], Any]) -> Any:
        """``make(rng, k)`` with the generator of segment k of ``stream``, made once."""
        return self._draws.get(stream, k, lambda rng: make(rng, k))

    @abc.abstractmethod
    def _render(self, k: int) -> np.ndarray:
        """The samples of 1-s segment k, shape (n_channels, segment_len)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_channels={self.n_channels}, seed={self.seed}, duration_s={self.duration_s})"


class ConstantSpeed:
    """Mixin of a scenario whose shaft turns at the constant ``shaft_hz_value`` [Hz]."""

    shaft_hz_value: float

    def shaft_hz(self, t) -> np.ndarray:
        """``shaft_hz_value`` at every time t [s]."""
        return np.full(np.shape(t), self.shaft_hz_value)

    def shaft_turns(self, t) -> np.ndarray:
        """The exact angle ``shaft_hz_value * t`` in revolutions."""
        return self.shaft_hz_value * np.asarray(t, dtype=np.float64)


def keyword_params(factory: Callable[..., Scenario]) -> list[str]:
    """The keyword-only constructor parameters of a scenario class, in MRO order, up to
    :class:`Scenario` (mixins included)."""
    names: list[str] = []
    for cls in getattr(factory, "__mro__", (factory,)):
        init = cls.__dict__.get("__init__") if isinstance(cls, type) else cls
        if init is None:
            continue
        for p in inspect.signature(init).parameters.values():
            if p.kind is p.KEYWORD_ONLY and p.name not in names:
                names.append(p.name)
        if isinstance(cls, type) and cls is Scenario:
            break
    return names
