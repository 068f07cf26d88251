"""Machine signal models: physical acceleration in m/s^2 at fs = 25 kHz.

Owns the simulated *machines* the firmware_sim board samples (the board, its
ADC and framing live in :mod:`firmware_sim.board`). The machine of seed 000
(section IV): a 3-phase, 4-pole, 3.7 kW induction motor at about 1720 rpm, so
f_r = 28.66 Hz, with an accelerometer on top of it; a motor is "faulty" above
7.1 mm/s velocity RMS (ISO 10816, "unacceptable"). Four scenarios:

==============  ===============================================================
``healthy``     the motor in good condition (ISO 10816 velocity RMS ~1.8 mm/s)
``faulty``      the same motor with unbalance/looseness (>7.1 mm/s) and an
                outer-race bearing defect (impacts at BPFO ringing at 3 kHz)
``degrading``   healthy -> faulty -> worse -> easing over ``duration_s``: the
                shape of the test input of seed 000, Figs. 14-16
``spikes``      the illustrative input of seed 000, Fig. 4: a random 100 Hz RMS
                sequence with 25 single-block spikes per second
``whirl``       seed 001 synthetic signal 1: journal-bearing run-up 0 -> 7000 rpm
                in 180 s with oil whirl (order 0.47) and whip (47 Hz)
``close_orders`` seed 001 synthetic signal 2: run-up 0 -> 3000 rpm in 5 s with
                the close orders 4 and 4.2
==============  ===============================================================

The two run-ups (:class:`RunUpScenario`) take their components from
:mod:`firmware_sim.order_signals` and can write their true component waveforms
beside a capture (:func:`write_truth`).

Determinism and chunk invariance
--------------------------------
Samples are generated in fixed 1-s segments (``fs`` samples). Every random
draw of segment k comes from a generator seeded with
``np.random.SeedSequence([seed, stream, k])`` where ``stream`` is the channel
index for what one sensor sees on its own (its noise) and
:data:`MACHINE_STREAM` for what the machine does (wander of the rotation
components, bearing impacts, spike positions), which all channels share.
Whatever reaches across a segment boundary (the ringing of a resonance, an
impact jittered over the boundary, the smooth wander) is recomputed from the
neighbouring segments' draws, never carried as state, so the samples of a
range depend only on (parameters, seed, channel) and never on how a caller
chunks its requests. The last segments are cached, so sequential reading
renders each segment once.
"""

from __future__ import annotations

import abc
import functools
import inspect
import math
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "MACHINE_STREAM",
    "DEFAULT_CHANNEL_GAINS",
    "Scenario",
    "MotorScenario",
    "HealthyMotor",
    "FaultyMotor",
    "DegradingMotor",
    "SpikesScenario",
    "RunUpScenario",
    "WhirlRunUp",
    "CloseOrdersRunUp",
    "SCENARIOS",
    "write_truth",
    "truth_key",
    "make_scenario",
    "velocity_rms",
]

#: ``SeedSequence([seed, MACHINE_STREAM, k])`` seeds the machine's own draws of
#: segment k (shared by all channels); channel c's draws use ``[seed, c, k]``.
MACHINE_STREAM = 1 << 16
#: Segment indices below 0 (the pre-boot neighbour of segment 0) are seeded
#: with ``[seed, stream, PRE_BOOT, -k]``, since SeedSequence takes no negatives.
PRE_BOOT = 1 << 32
#: Sensor gains of channels 0..3 (cycled for more channels): each channel is
#: the same machine seen by a sensor with its own gain and its own noise.
DEFAULT_CHANNEL_GAINS = (1.0, 0.8, 1.2, 0.9)
MAX_CHANNELS = 8  # PROTOCOL.md, STATUS: n_channels 1..8

# shaft angle quadrature (Scenario.shaft_turns): 8-node Gauss-Legendre on 10-ms panels,
# nodes mapped to [0, 1] and weights summing to 1
_TURN_PANEL = 0.01
_PANELS_PER_S = 100
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W

_SEGMENT_CACHE = 3  # rendered segments kept (current, previous, one spare)
_DRAW_CACHE = 6  # per-segment machine draws kept (k-1, k, k+1 and spares)


def _seed_entropy(seed: int, stream: int, k: int) -> list[int]:
    return [seed, stream, k] if k >= 0 else [seed, stream, PRE_BOOT, -k]


def _generator(seed: int, stream: int, k: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(_seed_entropy(seed, stream, k))))


# Gaussian noise by inverse-CDF lookup of 16-bit uniforms: the 65536 mid-point
# quantiles of N(0, 1), rescaled to unit variance (tails truncated at +-4.3 sigma).
# Four values per 64-bit PCG64 output: 4x faster than the ziggurat here, and the
# bit generator's stream is stable across numpy versions.
@functools.lru_cache(maxsize=1)
def _gauss_table() -> np.ndarray:
    """The 65536 standard-normal quantiles (scipy imported only when a signal is made,
    so `cmsensord` can list the scenarios without loading scipy)."""
    from scipy.special import ndtri

    table = ndtri((np.arange(65536) + 0.5) / 65536)
    return table / np.sqrt(np.mean(table**2))


def _gauss(rng: np.random.Generator, n: int) -> np.ndarray:
    """n standard-normal values (quantised to 16 bits, see _GAUSS_TABLE)."""
    raw = rng.bit_generator.random_raw((n + 3) // 4).astype("<u8", copy=False)
    return _gauss_table().take(raw.view("<u2")[:n])


def _smooth_ramp(u: np.ndarray) -> np.ndarray:
    """0 -> 1 over u in [0, 1] with zero slope at both ends (raised cosine)."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


def _cubic_bspline(x: np.ndarray) -> np.ndarray:
    """The cardinal cubic B-spline, centred on 0, support (-2, 2)."""
    ax = np.abs(x)
    out = np.zeros_like(ax)
    m1 = ax < 1.0
    m2 = (ax >= 1.0) & (ax < 2.0)
    out[m1] = 2.0 / 3.0 - ax[m1] ** 2 + 0.5 * ax[m1] ** 3
    out[m2] = (2.0 - ax[m2]) ** 3 / 6.0
    return out


def velocity_rms(accel: np.ndarray, fs: float, band: tuple[float, float] = (10.0, 1000.0)) -> np.ndarray:
    """Velocity RMS in mm/s of acceleration records (m/s^2, last axis = time).

    The ISO 10816 measure: velocity = acceleration / (j 2 pi f) in the frequency
    domain, RMS over ``band`` (10-1000 Hz) by Parseval. Use records of several
    seconds so the band edges and the 1x line are resolved.
    """
    x = np.asarray(accel, dtype=np.float64)
    n = x.shape[-1]
    spec = np.fft.rfft(x, axis=-1)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    sel = (f >= band[0]) & (f <= band[1])
    v = spec[..., sel] / (2j * np.pi * f[sel])
    # one-sided spectrum: each bin (not DC/Nyquist, outside the band) counts twice
    power = 2.0 * np.sum(np.abs(v) ** 2, axis=-1) / n**2
    return 1e3 * np.sqrt(power)


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
        self._draws: OrderedDict[tuple[int, int], Any] = OrderedDict()
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

    def _cached_draw(self, stream: int, k: int, make: Callable[[np.random.Generator], Any]) -> Any:
        key = (stream, k)
        d = self._draws.get(key)
        if d is None:
            d = make(_generator(self.seed, stream, k), k)
            self._draws[key] = d
            while len(self._draws) > _DRAW_CACHE:
                self._draws.popitem(last=False)
        else:
            self._draws.move_to_end(key)
        return d

    @abc.abstractmethod
    def _render(self, k: int) -> np.ndarray:
        """The samples of 1-s segment k, shape (n_channels, segment_len)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_channels={self.n_channels}, seed={self.seed}, duration_s={self.duration_s})"


class MotorScenario(Scenario):
    """The induction motor of seed 000, section IV, with a fault-severity knob s(t).

    Physical model (acceleration at the sensor, channel c with gain g_c)::

        a_c(t) = g_c * [ sum_h Re{ A_h(t) exp(j 2 pi f_h t) }
                         + R * (impacts(t) + sigma_r w_m(t)) ] + noise_rms * w_c(t)

    * rotation components h = 1x, 2x, 3x of f_r = ``shaft_hz`` (28.66 Hz: 1720
      rpm, seed 000) and the electromagnetic 2x line component at
      2 * ``line_hz`` = 120 Hz (60 Hz mains: a 4-pole motor has 1800 rpm
      synchronous speed, 1720 rpm is 4.4 % slip). Their complex amplitudes
      A_h(t) = (healthy_h + s(t) * fault_h) * W_h(t) grow with the severity knob
      s(t) (unbalance at 1x, looseness/misalignment at 2x and 3x) and wander
      slowly: W_h is a cubic B-spline through random knots every 0.5 s with
      relative amplitude std ``wander_amp`` and phase std ``wander_phase`` [rad]
      about a fixed random phase. Levels are given as ISO 10816 velocity RMS in
      mm/s (acceleration amplitude = v * sqrt(2) * 2 pi f_h).
    * outer-race bearing defect: an impact each time a ball passes the defect,
      at BPFO = ``bpfo_ratio`` * f_r (3.58 for a 6206 bearing: 9 balls of
      9.525 mm on a 46 mm pitch circle, BPFO = 9/2 (1 - 9.525/46) f_r = 3.57 f_r),
      with time jitter (std ``impact_jitter`` of the period: ball slip), a
      log-normal peak (median ``impact_peak`` * s**``impact_gamma`` m/s^2,
      log-std ``impact_sigma``), present with probability
      min(1, s / ``impact_onset``) (the defect strikes only part of the passes:
      load zone, lubricant film), so the 100 Hz RMS shows isolated jumps.
      Each impact rings the housing resonance R: a 2-pole resonator at
      ``resonance_hz`` (3 kHz) with damping ratio ``resonance_zeta``, unit
      ringing peak per unit impact.
    * structure noise: the machine's broadband forces w_m (white) ring the same
      resonance R, scaled so the resonance band carries ``resonance_noise_rms``
      m/s^2 RMS (shared by all channels, like the components above);
    * sensor noise: each channel's own white noise w_c of RMS ``noise_rms`` (the
      broadband floor, flat to fs/2).

    White noise is Gaussian, quantised to 16 bits (see ``_gauss_table``).

    Calibration against seed 000 (the paper's parameters must give the
    paper's behaviour: n = 10, R_min = 4e-3, R_max = 0.13, z_c = 2.8, c = 0.4,
    f_r = 28.66 Hz, N = 10). The outliers an AKF counts are the *isolated jumps*
    of the 100 Hz RMS sequence that exceed its adaptive bound x̂⁻ ± z_c sqrt(Y)
    (Y >= R), so the bearing impacts, not the smooth 1x/2x content, set the
    severity. The impact defaults (``impact_peak`` 20 m/s^2, ``impact_gamma``
    3, ``impact_onset`` 3, ``impact_sigma`` 0.4) were chosen by sweeping them
    and running the bank on 200-300 s of board output per setting and seed
    (seeds 0-3): s = 0 gives no outlier at all in AKF_1 (healthy: S_idx = 0,
    as the paper's healthy motor is anomaly-free for R > R_min); s = 0.7 gives
    S_idx ~ 0.1, s = 0.85 ~ 0.3, s = 1 (faulty) 0.5-1.0 depending on the seed
    (the paper's faulty motor is detected up to R just under R_max); s = 1.4
    gives 1.0, a failure (AKF_10 flags). ``tests/test_scenarios.py`` holds
    these against the whole chain.

    The defaults put the healthy motor (s = 0) at about 1.8 mm/s velocity RMS
    (10-1000 Hz, ISO 10816 "good/satisfactory"; about 0.68 m/s^2 acceleration
    RMS) and the faulty one (s = 1) at about 8.3 mm/s (> 7.1 mm/s,
    "unacceptable"; about 2.2 m/s^2 acceleration RMS), for a channel of gain 1.
    """

    name = "motor"
    _KNOT_DT = 0.5  # s between wander knots (two per segment)

    def __init__(self, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                 fs: int = 25000, channel_gains: tuple[float, ...] | None = None,
                 shaft_hz: float = 28.66, line_hz: float = 60.0,
                 v1x: float = 1.5, v2x: float = 0.8, v3x: float = 0.0, v_line: float = 0.5,
                 fault_v1x: float = 6.0, fault_v2x: float = 2.5, fault_v3x: float = 1.5,
                 wander_amp: float = 0.08, wander_phase: float = 0.1,
                 noise_rms: float = 0.35, resonance_noise_rms: float = 0.25,
                 resonance_hz: float = 3000.0, resonance_zeta: float = 0.05,
                 bpfo_ratio: float = 3.58, impact_peak: float = 20.0, impact_sigma: float = 0.4,
                 impact_jitter: float = 0.01, impact_onset: float = 3.0,
                 impact_gamma: float = 3.0):
        super().__init__(n_channels=n_channels, duration_s=duration_s, seed=seed, fs=fs,
                         channel_gains=channel_gains)
        for key, val in dict(shaft_hz=shaft_hz, line_hz=line_hz, resonance_hz=resonance_hz,
                             resonance_zeta=resonance_zeta, bpfo_ratio=bpfo_ratio,
                             impact_onset=impact_onset).items():
            if not val > 0:
                raise ValueError(f"{key} must be > 0, got {val!r}")
        for key, val in dict(v1x=v1x, v2x=v2x, v3x=v3x, v_line=v_line, fault_v1x=fault_v1x,
                             fault_v2x=fault_v2x, fault_v3x=fault_v3x, wander_amp=wander_amp,
                             wander_phase=wander_phase, noise_rms=noise_rms,
                             resonance_noise_rms=resonance_noise_rms, impact_peak=impact_peak,
                             impact_sigma=impact_sigma, impact_jitter=impact_jitter,
                             impact_gamma=impact_gamma).items():
            if not val >= 0:
                raise ValueError(f"{key} must be >= 0, got {val!r}")
        if not resonance_hz < fs / 2:
            raise ValueError(f"resonance_hz must be below fs/2 = {fs / 2}, got {resonance_hz}")
        self.shaft_hz_nominal = self.shaft_hz_value = float(shaft_hz)
        self.line_hz = float(line_hz)
        self.v1x, self.v2x, self.v3x, self.v_line = map(float, (v1x, v2x, v3x, v_line))
        self.fault_v1x, self.fault_v2x, self.fault_v3x = map(float, (fault_v1x, fault_v2x, fault_v3x))
        self.wander_amp, self.wander_phase = float(wander_amp), float(wander_phase)
        self.noise_rms, self.resonance_noise_rms = float(noise_rms), float(resonance_noise_rms)
        self.resonance_hz, self.resonance_zeta = float(resonance_hz), float(resonance_zeta)
        self.bpfo_ratio = float(bpfo_ratio)
        self.impact_peak, self.impact_sigma = float(impact_peak), float(impact_sigma)
        self.impact_jitter, self.impact_onset = float(impact_jitter), float(impact_onset)
        self.impact_gamma = float(impact_gamma)

        L = self.segment_len
        fr = self.shaft_hz_value
        # (frequency, healthy velocity RMS, fault velocity RMS at s = 1), mm/s
        comps = [(fr, self.v1x, self.fault_v1x), (2 * fr, self.v2x, self.fault_v2x),
                 (3 * fr, self.v3x, self.fault_v3x), (2 * self.line_hz, self.v_line, 0.0)]
        comps = [c for c in comps if c[1] > 0 or c[2] > 0]
        self._freqs = np.array([c[0] for c in comps])
        to_acc = 1e-3 * math.sqrt(2.0) * 2.0 * np.pi * self._freqs  # mm/s RMS -> m/s^2 peak
        self._amp_h = np.array([c[1] for c in comps]) * to_acc
        self._amp_f = np.array([c[2] for c in comps]) * to_acc
        m = np.arange(L)
        H = len(comps)
        # carrier tables: row 2h = cos(w_h m), row 2h+1 = sin(w_h m), m = 0..L-1
        self._carriers = np.empty((2 * H, L))
        for h, f in enumerate(self._freqs):
            ang = 2.0 * np.pi * f * m / fs
            self._carriers[2 * h] = np.cos(ang)
            self._carriers[2 * h + 1] = np.sin(ang)
        # wander basis over one segment: knots 2k-1 .. 2k+3 (spacing _KNOT_DT)
        self._knots_per_seg = int(round(1.0 / self._KNOT_DT))
        x = m / (fs * self._KNOT_DT)
        self._basis = np.stack([_cubic_bspline(x + 1.0 - jj) for jj in range(self._knots_per_seg + 3)])
        base = _generator(self.seed, MACHINE_STREAM, PRE_BOOT + 1)  # fixed phases of the components
        self._phase0 = base.uniform(0.0, 2.0 * np.pi, H)

        # housing resonance R: y[n] = 2 r cos(wd) y[n-1] - r^2 y[n-2] + sin(wd) x[n]
        wn = 2.0 * np.pi * self.resonance_hz / fs
        zeta = self.resonance_zeta
        if zeta >= 1.0:
            raise ValueError(f"resonance_zeta must be < 1, got {zeta}")
        r = math.exp(-zeta * wn)
        wd = wn * math.sqrt(1.0 - zeta * zeta)
        self._res_b = np.array([math.sin(wd)])
        self._res_a = np.array([1.0, -2.0 * r * math.cos(wd), r * r])
        tau = 1.0 / (zeta * wn)  # envelope time constant in samples
        self._warmup = int(math.ceil(25.0 * tau))  # e^-25: the ringing carried across a boundary
        if self._warmup > L:
            raise ValueError(f"resonance_zeta={zeta} rings longer than a segment; use >= {25 / (wn * L):.2g}")
        from scipy.signal import lfilter

        h = lfilter(self._res_b, self._res_a, np.r_[1.0, np.zeros(self._warmup * 2)])
        self._res_noise_gain = self.resonance_noise_rms / math.sqrt(float(np.sum(h * h)))
        self.bpfo_hz = self.bpfo_ratio * fr

    # -- physics ---------------------------------------------------------------
    def shaft_hz(self, t) -> np.ndarray:
        return np.full(np.shape(t), self.shaft_hz_value)

    def shaft_turns(self, t) -> np.ndarray:
        return self.shaft_hz_value * np.asarray(t, dtype=np.float64)

    # -- per-segment draws -----------------------------------------------------
    def _machine_draws(self, k: int) -> dict[str, np.ndarray]:
        return self._cached_draw(MACHINE_STREAM, k, self._make_machine_draws)

    def _make_machine_draws(self, rng: np.random.Generator, k: int) -> dict[str, np.ndarray]:
        H = len(self._freqs)
        kp = self._knots_per_seg
        # wander knots j = kp*k .. kp*k + kp - 1 of every component
        amp = 1.0 + self.wander_amp * rng.standard_normal((H, kp))
        ph = self.wander_phase * rng.standard_normal((H, kp))
        t_knots = (kp * k + np.arange(kp)) * self._KNOT_DT
        s = np.asarray(self.severity(t_knots), dtype=np.float64)
        level = self._amp_h[:, None] + s[None, :] * self._amp_f[:, None]
        knots = level * amp * np.exp(1j * (self._phase0[:, None] + ph))
        # impacts whose nominal time j / BPFO lies in segment k
        L = self.segment_len
        fs = self.fs
        period = fs / self.bpfo_hz  # samples
        j0 = math.ceil(k * L / period)
        j1 = math.ceil((k + 1) * L / period)
        nj = max(j1 - j0, 0)
        jitter = rng.standard_normal(nj)
        mag = rng.standard_normal(nj)
        present_u = rng.random(nj)
        if k < 0:  # before boot: no impacts, no structure noise to ring on into segment 0
            return {"knots": knots, "pos": np.empty(0), "amp": np.empty(0), "white": np.zeros(L)}
        white = _gauss(rng, L)
        pos = (np.arange(j0, j1) + self.impact_jitter * jitter) * period
        s_imp = np.asarray(self.severity(pos / fs), dtype=np.float64)
        p = np.minimum(1.0, s_imp / self.impact_onset)
        a = self.impact_peak * s_imp ** self.impact_gamma * np.exp(self.impact_sigma * mag) * (present_u < p)
        keep = a > 0
        return {"knots": knots, "pos": pos[keep], "amp": a[keep], "white": white}

    # -- rendering ---------------------------------------------------------------
    def _render(self, k: int) -> np.ndarray:
        L = self.segment_len
        W = self._warmup
        prev, cur, nxt = (self._machine_draws(k + d) for d in (-1, 0, 1))
        # rotation/line components: Re{ sum_j K_hj B_j(m) e^{j(phi_hk + w_h m)} }
        knots = np.concatenate([prev["knots"][:, -1:], cur["knots"], nxt["knots"]], axis=1)
        phi = 2.0 * np.pi * np.mod(self._freqs * float(k) * (L / self.fs), 1.0)
        g = knots * np.exp(1j * phi)[:, None]
        coef = np.empty((2 * g.shape[0], g.shape[1]))
        coef[0::2] = g.real
        coef[1::2] = -g.imag
        env = coef @ self._basis  # (2H, L)
        machine = np.einsum("ij,ij->j", env, self._carriers)
        # bearing impacts as fractional-sample impulses on [kL - W, kL + L)
        origin = k * L - W
        pos = np.concatenate([prev["pos"], cur["pos"], nxt["pos"]]) - origin
        amp = np.concatenate([prev["amp"], cur["amp"], nxt["amp"]])
        # an impulse at p splits into (1 - frac) at floor(p) and frac at floor(p) + 1;
        # indices are shifted by one so floor(p) = -1 is representable
        sel = (pos > -1.0) & (pos < W + L)
        pos, amp = pos[sel], amp[sel]
        i1 = np.floor(pos).astype(np.int64) + 1
        frac = pos - (i1 - 1)
        n_imp = W + L + 2
        imp = (np.bincount(i1, weights=amp * (1.0 - frac), minlength=n_imp)
               + np.bincount(i1 + 1, weights=amp * frac, minlength=n_imp))[1:W + L + 1]
        # the housing resonance rung by the impacts and the structure noise; the
        # warm-up replays the last W inputs of segment k-1 from zero state
        u = np.concatenate([prev["white"][L - W:], cur["white"]])
        u *= self._res_noise_gain
        u += imp
        from scipy.signal import lfilter

        machine += lfilter(self._res_b, self._res_a, u)[W:]
        out = np.empty((self.n_channels, L))
        for c in range(self.n_channels):
            row = out[c]
            np.multiply(machine, self.channel_gains[c], out=row)
            if self.noise_rms:
                row += self.noise_rms * _gauss(_generator(self.seed, c, k), L)
        return out


class HealthyMotor(MotorScenario):
    """``healthy``: the seed-000 motor in good condition, s(t) = 0.

    See :class:`MotorScenario` for the physical model. Defaults: 1x 1.5, 2x 0.8,
    120 Hz 0.5 mm/s RMS plus broadband and 3-kHz resonance noise: about 1.8 mm/s
    velocity RMS (ISO 10816 "good/satisfactory"), 0.68 m/s^2 acceleration RMS.
    """

    name = "healthy"
    description = ("3.7 kW 4-pole induction motor at 1720 rpm (f_r 28.66 Hz) in good condition: "
                   "1x/2x/120 Hz + noise, ~1.8 mm/s velocity RMS")

    def severity(self, t) -> np.ndarray:
        return np.zeros(np.shape(t))


class FaultyMotor(MotorScenario):
    """``faulty``: the seed-000 motor above 7.1 mm/s (ISO 10816 "unacceptable"), s(t) = ``level``.

    See :class:`MotorScenario`. At ``level`` = 1 the 1x reaches 7.5 mm/s, 2x 3.3,
    3x 1.5 mm/s: about 8.3 mm/s velocity RMS, and outer-race impacts at BPFO =
    3.58 f_r = 102.6 Hz ring the 3 kHz resonance; about 2.2 m/s^2 acceleration RMS.
    """

    name = "faulty"
    description = ("the same motor with unbalance/looseness (~8.3 mm/s velocity RMS > 7.1) and an "
                   "outer-race bearing defect (impacts at BPFO = 3.58 f_r ringing at 3 kHz)")

    def __init__(self, *, level: float = 1.0, **kwargs):
        if not level >= 0:
            raise ValueError(f"level must be >= 0, got {level!r}")
        self.level = float(level)
        super().__init__(**kwargs)

    def severity(self, t) -> np.ndarray:
        return np.full(np.shape(t), self.level)


class DegradingMotor(MotorScenario):
    """``degrading``: healthy -> faulty -> worse -> easing over ``duration_s`` (seed 000, Figs. 14-16).

    See :class:`MotorScenario`. The knob s(t), with u = t / duration_s, is
    piecewise smooth (raised-cosine ramps, zero slope at the joins):

    * u < ``onset`` (0.25): 0, the healthy motor;
    * ``onset`` -> ``faulty_at`` (0.6): rises 0 -> 1, the faulty level
      (> 7.1 mm/s), like the test input of Fig. 14;
    * ``faulty_at`` -> ``peak_at`` (0.8): rises 1 -> ``peak_level`` (1.4, 40 %
      above the faulty level; the failure of Fig. 15 is detected at 2683 s of
      3600, u = 0.745; with the calibrated impacts the bank reports failure
      at u ~ 0.63-0.67);
    * ``peak_at`` -> 1: eases to ``end_level`` (0.7, below the faulty level;
      Fig. 16 shows the severity index falling after 3100 s, u = 0.86; here it
      falls from u ~ 0.9);
    * after duration_s it stays at ``end_level``.
    """

    name = "degrading"
    description = ("healthy -> faulty (at 60 %) -> 40 % worse (at 80 %) -> easing below the faulty "
                   "level by the end of --duration (seed 000, Figs. 14-16)")

    def __init__(self, *, onset: float = 0.25, faulty_at: float = 0.6, peak_at: float = 0.8,
                 peak_level: float = 1.4, end_level: float = 0.7, **kwargs):
        if not 0.0 <= onset < faulty_at < peak_at < 1.0:
            raise ValueError("degrading needs 0 <= onset < faulty_at < peak_at < 1, got "
                             f"onset={onset}, faulty_at={faulty_at}, peak_at={peak_at}")
        if not (peak_level >= 0 and end_level >= 0):
            raise ValueError("peak_level and end_level must be >= 0")
        self.onset, self.faulty_at, self.peak_at = float(onset), float(faulty_at), float(peak_at)
        self.peak_level, self.end_level = float(peak_level), float(end_level)
        super().__init__(**kwargs)

    def severity(self, t) -> np.ndarray:
        u = np.asarray(t, dtype=np.float64) / self.duration_s
        a, b, c = self.onset, self.faulty_at, self.peak_at
        s = np.where(u < b, _smooth_ramp((u - a) / (b - a)),
                     np.where(u < c, 1.0 + (self.peak_level - 1.0) * _smooth_ramp((u - b) / (c - b)),
                              self.peak_level + (self.end_level - self.peak_level)
                              * _smooth_ramp((u - c) / (1.0 - c))))
        return s


class SpikesScenario(Scenario):
    """``spikes``: the illustrative input of seed 000, Fig. 4, at the observation level.

    The 100 Hz RMS sequence is "a random signal with 25 spikes per second"
    (section III-E). Physical model: white Gaussian noise whose standard
    deviation is constant within each ``block_len``-sample block (250: the
    board's RMS block, so one block = one observation) and drawn per block as
    ``base_rms`` * exp(``base_spread`` * N(0,1)); in every second,
    ``spikes_per_s`` (25) of the blocks, evenly spaced or at random positions with no two
    adjacent (so each spike is a single observation, one rise and one fall,
    as in the paper), get ``spike_rms`` * exp(``spike_spread`` * N(0,1)) instead.
    The block RMS is then the block's level times (1 +- 1/sqrt(2 * 250)).
    Block levels and spike positions are the machine's (shared by all
    channels, times the channel gain); the noise is each channel's own.
    ``severity`` is 1 inside spike blocks and 0 elsewhere (the ground truth).
    Defaults: base 1.0 m/s^2 with 5 % spread (std of the observation about
    0.07), spikes at 3.0 m/s^2, evenly spaced (``spacing="even"``: every 4th
    block, as Fig. 5's exact count of 25 implies; ``"random"`` places them at
    random non-adjacent blocks). With R = 1e-2 and N = 10 the AKF then counts
    exactly 25 outliers a second, 50 without scaling (Fig. 5).
    """

    name = "spikes"
    description = ("seed 000 Fig. 4: random 100 Hz RMS sequence (base ~1 m/s^2) with 25 "
                   "single-block spikes per second (~3 m/s^2)")

    def __init__(self, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                 fs: int = 25000, channel_gains: tuple[float, ...] | None = None,
                 base_rms: float = 1.0, base_spread: float = 0.05, spike_rms: float = 3.0,
                 spike_spread: float = 0.05, spikes_per_s: int = 25, block_len: int = 250,
                 shaft_hz: float = 28.66, spacing: str = "even"):
        super().__init__(n_channels=n_channels, duration_s=duration_s, seed=seed, fs=fs,
                         channel_gains=channel_gains)
        if not isinstance(block_len, (int, np.integer)) or block_len <= 0 or fs % block_len:
            raise ValueError(f"block_len must be a positive divisor of fs={fs}, got {block_len!r}")
        nb = fs // block_len
        if not isinstance(spikes_per_s, (int, np.integer)) or not 0 <= spikes_per_s <= nb // 2:
            raise ValueError(f"spikes_per_s must be an integer 0..{nb // 2} (non-adjacent blocks "
                             f"among {nb} per second), got {spikes_per_s!r}")
        for key, val in dict(base_rms=base_rms, base_spread=base_spread, spike_rms=spike_rms,
                             spike_spread=spike_spread, shaft_hz=shaft_hz).items():
            if not val >= 0:
                raise ValueError(f"{key} must be >= 0, got {val!r}")
        self.base_rms, self.base_spread = float(base_rms), float(base_spread)
        self.spike_rms, self.spike_spread = float(spike_rms), float(spike_spread)
        self.spikes_per_s, self.block_len = int(spikes_per_s), int(block_len)
        self.shaft_hz_value = float(shaft_hz)
        self._blocks_per_seg = nb
        if spacing not in ("even", "random"):
            raise ValueError(f"spacing must be 'even' or 'random', got {spacing!r}")
        if spacing == "even" and spikes_per_s and nb % spikes_per_s:
            raise ValueError(f"even spacing needs spikes_per_s dividing {nb}, got {spikes_per_s}")
        self.spacing = spacing

    def shaft_hz(self, t) -> np.ndarray:
        """Nominal (the signal has no rotational content): ``shaft_hz``, 28.66 Hz."""
        return np.full(np.shape(t), self.shaft_hz_value)

    def shaft_turns(self, t) -> np.ndarray:
        return self.shaft_hz_value * np.asarray(t, dtype=np.float64)

    def _levels(self, k: int) -> dict[str, np.ndarray]:
        return self._cached_draw(MACHINE_STREAM, k, self._make_levels)

    def _make_levels(self, rng: np.random.Generator, k: int) -> dict[str, np.ndarray]:
        nb, m = self._blocks_per_seg, self.spikes_per_s
        level = self.base_rms * np.exp(self.base_spread * rng.standard_normal(nb))
        if self.spacing == "even":
            # Fig. 4/5: 25 spikes a second, one every 4th observation
            spike_pos = np.arange(m) * (nb // m) if m else np.empty(0, dtype=np.int64)
        else:
            # m non-adjacent positions among 0..nb-2 (nb-1 is never a spike, so a spike
            # in the last block of a second cannot touch one in the next second's first)
            c = np.sort(rng.choice(nb - m, size=m, replace=False))
            spike_pos = c + np.arange(m)
        level[spike_pos] = self.spike_rms * np.exp(self.spike_spread * rng.standard_normal(m))
        is_spike = np.zeros(nb, dtype=bool)
        is_spike[spike_pos] = True
        return {"level": level, "spike": is_spike}

    def severity(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        idx = np.floor(t * self.fs).astype(np.int64)
        if idx.size and idx.min() < 0:
            raise ValueError("severity needs t >= 0")
        seg, rem = np.divmod(idx, self.segment_len)
        blk = rem // self.block_len
        out = np.zeros(t.shape)
        for k in np.unique(seg):
            m = seg == k
            out[m] = self._levels(int(k))["spike"][blk[m]]
        return out

    def _render(self, k: int) -> np.ndarray:
        nb, bl = self._blocks_per_seg, self.block_len
        level = self._levels(k)["level"]
        out = np.empty((self.n_channels, self.segment_len))
        for c in range(self.n_channels):
            w = _gauss(_generator(self.seed, c, k), self.segment_len)
            np.multiply(w.reshape(nb, bl), (self.channel_gains[c] * level)[:, None],
                        out=out[c].reshape(nb, bl))
        return out


class RunUpScenario(Scenario):
    """A seed-001 synthetic run-up (:mod:`firmware_sim.order_signals`) on the board.

    Acceleration of channel c (gain g_c), in m/s^2 as the paper gives the
    amplitudes::

        a_c(t) = g_c * ( sum_i x_i(t) + sigma * w_c(t) ),   sigma = noise * ref_rms

    where x_i are the run-up's components (``RunUp.signals``: orders
    A(t) cos(2 pi o turns(t)) and fixed-frequency lines), evaluated at the
    sample times (k * fs + m) / fs of each 1-s segment k (so chunking never
    changes a sample), and w_c is the channel's own white Gaussian noise with
    std 1 (16-bit quantised, see ``_gauss``) drawn per segment from
    ``SeedSequence([seed, c, k])``. The noise std is ``noise`` (default 0.05,
    issue 3 section 5) times the RMS of the order-1 component at its largest
    (``RunUp.ref_rms``); it is scaled by the gain like the signal, so every
    channel has the paper's signal-to-noise ratio. The noise is the only random
    part; components and speed are analytic.

    ``shaft_hz`` = rpm(t) / 60 and ``shaft_turns`` = the exact integral of the
    run-up (``RunUp.turns``), so the tacho edges are exact crossings.
    The run-up lasts the paper's time (``natural_duration_s``) times
    ``time_scale``, or ``runup_s`` seconds if given; ``rpm_max`` overrides the
    top speed (the components' switch-on speeds stay those of the paper).
    After the run-up the speed and the amplitudes hold their end values, so a
    ``duration_s`` longer than the run-up holds the top speed. ``duration_s``
    itself does not shape the signal.
    """

    name = "runup"
    natural_duration_s: float = 1.0
    _factory: Callable[..., Any] | None = None

    def __init__(self, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                 fs: int = 25000, channel_gains: tuple[float, ...] | None = None,
                 noise: float = 0.05, time_scale: float = 1.0, runup_s: float | None = None,
                 rpm_max: float | None = None):
        super().__init__(n_channels=n_channels, duration_s=duration_s, seed=seed, fs=fs,
                         channel_gains=channel_gains)
        if not (noise >= 0 and math.isfinite(noise)):
            raise ValueError(f"noise must be >= 0 (a fraction of the order-1 RMS), got {noise!r}")
        if not (time_scale > 0 and math.isfinite(time_scale)):
            raise ValueError(f"time_scale must be > 0, got {time_scale!r}")
        if runup_s is not None and not (runup_s > 0 and math.isfinite(runup_s)):
            raise ValueError(f"runup_s must be a positive number of seconds, got {runup_s!r}")
        if runup_s is not None and time_scale != 1.0:
            raise ValueError("give either runup_s or time_scale, not both")
        if rpm_max is not None and not (rpm_max > 0 and math.isfinite(rpm_max)):
            raise ValueError(f"rpm_max must be > 0, got {rpm_max!r}")
        self.noise = float(noise)
        self.time_scale = float(time_scale)
        self.runup_s = float(runup_s) if runup_s is not None else self.natural_duration_s * self.time_scale
        kwargs = {"duration_s": self.runup_s}
        if rpm_max is not None:
            kwargs["rpm_max"] = float(rpm_max)
        self.runup = type(self)._factory(**kwargs)
        self.rpm_max = self.runup.rpm_max
        self.noise_std = self.noise * float(self.runup.ref_rms())

    # -- physics ---------------------------------------------------------------
    def shaft_hz(self, t) -> np.ndarray:
        return self.runup.rpm(t) / 60.0

    def shaft_turns(self, t) -> np.ndarray:
        return self.runup.turns(t)

    def severity(self, t) -> np.ndarray:
        return np.zeros(np.shape(t))

    def components(self, t) -> dict[str, np.ndarray]:
        """The true component waveforms at times t [s] (gain 1, no noise)."""
        return self.runup.signals(t)

    def _render(self, k: int) -> np.ndarray:
        L = self.segment_len
        t = (k * L + np.arange(L, dtype=np.int64)) / self.fs
        clean = self.runup.clean(t)
        out = np.empty((self.n_channels, L))
        for c in range(self.n_channels):
            row = out[c]
            if self.noise_std:
                np.multiply(_gauss(_generator(self.seed, c, k), L), self.noise_std, out=row)
                row += clean
            else:
                row[:] = clean
            row *= self.channel_gains[c]
        return out


def _lazy_runup(name: str) -> Callable[..., Any]:
    def make(**kwargs):
        from . import order_signals

        return order_signals.RUNUPS[name](**kwargs)

    return staticmethod(make)


class WhirlRunUp(RunUpScenario):
    """``whirl``: seed 001 synthetic signal 1 (``order_signals.whirl_runup``).

    A journal-bearing rotor runs up 0 -> 7000 rpm in 180 s: order 1 (unbalance)
    1 -> 4 peak, order 0.47 (oil whirl) 2 -> 4 between 3000 and 6000 rpm, a
    47-Hz line (oil whip) 4 -> 6 from 6000 rpm; noise 5 % of the order-1 RMS.
    """

    name = "whirl"
    description = ("seed 001 signal 1: journal-bearing run-up 0 -> 7000 rpm in 180 s, order 1, "
                   "oil whirl (order 0.47, 3000-6000 rpm) and whip (47 Hz from 6000 rpm)")
    natural_duration_s = 180.0
    _factory = _lazy_runup("whirl")


class CloseOrdersRunUp(RunUpScenario):
    """``close_orders``: seed 001 synthetic signal 2 (``order_signals.close_orders_runup``).

    Run-up 0 -> 3000 rpm in 5 s: order 1 with RMS 2, order 4 with RMS 0 -> 10
    and order 4.2 with RMS 2 -> 12 (peaks up to 17 m/s^2, inside the board's
    +-20 g range); noise 5 % of the order-1 RMS.
    """

    name = "close_orders"
    description = ("seed 001 signal 2: run-up 0 -> 3000 rpm in 5 s with order 1 and the close "
                   "orders 4 and 4.2 (RMS up to 12 m/s^2)")
    natural_duration_s = 5.0
    _factory = _lazy_runup("close_orders")


def truth_key(component_name: str) -> str:
    """The .npz key of a component in a truth file: spaces become underscores ("order_0.47")."""
    return component_name.replace(" ", "_")


def write_truth(scenario: Scenario, path, duration_s: float, *, rate: float | None = None,
                channel: int = 0, chunk_s: float = 10.0) -> dict[str, Any]:
    """Write the true waveforms of ``scenario`` for ``duration_s`` seconds to an .npz file.

    Arrays (one value per truth sample n at t = n / rate, n = 0 .. floor(duration * rate) - 1):

    * ``t`` float64 [s]; ``rpm`` float64; ``turns`` float64 (shaft revolutions since t = 0);
    * one float32 array per component, in m/s^2 as channel ``channel`` sees it (times
      its gain), keyed by :func:`truth_key` of its name (``order_1``, ``order_0.47``,
      ``47_Hz``, ``order_4``, ``order_4.2``); run-up scenarios only;
    * ``accel`` float32: the channel's acceleration exactly as the board samples it
      (components + noise, before the ADC), when ``rate`` divides ``fs`` (the truth
      samples are then board samples);
    * scalars/metadata: ``fs``, ``rate``, ``channel``, ``gain``, ``noise_std``
      (m/s^2, of the channel), ``components`` (the original names), ``keys``,
      ``scenario``, ``seed``.

    ``rate`` defaults to the board rate ``fs``. Streams each array into the zip in
    ``chunk_s`` pieces (bounded memory: 180 s at 25 kHz writes 4.5 M samples per
    array). Returns {"samples", "keys"}.
    """
    import zipfile

    from numpy.lib import format as npformat

    fs = scenario.fs
    rate = float(fs if rate is None else rate)
    if not (rate > 0 and math.isfinite(rate)) or rate > fs:
        raise ValueError(f"truth rate must be in (0, fs={fs}] Hz, got {rate!r}")
    if not 0 <= channel < scenario.n_channels:
        raise ValueError(f"channel must be 0..{scenario.n_channels - 1}, got {channel}")
    if not duration_s > 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s!r}")
    n = int(math.floor(duration_s * rate + 1e-9))
    step = fs / rate
    sub = int(round(step)) if abs(step - round(step)) < 1e-9 else None
    gain = float(scenario.channel_gains[channel])
    comps_fn = getattr(scenario, "components", None)
    names = list(comps_fn(np.zeros(1))) if comps_fn is not None else []
    chunk = max(1, int(chunk_s * rate))

    def times(a: int, b: int) -> np.ndarray:
        if sub is not None:  # the board's own sample times, computed the way the scenario does
            return (np.arange(a, b, dtype=np.int64) * sub) / fs
        return np.arange(a, b, dtype=np.int64) / rate

    series: list[tuple[str, str, Callable[[int, int], np.ndarray]]] = [
        ("t", "<f8", times),
        ("rpm", "<f8", lambda a, b: 60.0 * np.asarray(scenario.shaft_hz(times(a, b)), dtype=np.float64)),
        ("turns", "<f8", lambda a, b: scenario.shaft_turns(times(a, b))),
    ]
    for name in names:
        series.append((truth_key(name), "<f4",
                       lambda a, b, name=name: gain * comps_fn(times(a, b))[name]))
    if sub is not None:
        series.append(("accel", "<f4",
                       lambda a, b: scenario.samples(a * sub, (b - a - 1) * sub + 1)[channel, ::sub]))
    meta = {
        "fs": np.array(fs), "rate": np.array(rate), "channel": np.array(channel),
        "gain": np.array(gain), "noise_std": np.array(gain * float(getattr(scenario, "noise_std", 0.0))),
        "components": np.array(names, dtype=str), "keys": np.array([truth_key(x) for x in names], dtype=str),
        "scenario": np.array(scenario.name), "seed": np.array(scenario.seed),
    }
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for key, dtype, fn in series:
            with zf.open(key + ".npy", "w", force_zip64=True) as f:
                npformat.write_array_header_1_0(
                    f, {"descr": npformat.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
                        "shape": (n,)})
                for a in range(0, n, chunk):
                    b = min(n, a + chunk)
                    f.write(np.ascontiguousarray(fn(a, b), dtype=dtype).tobytes())
        for key, arr in meta.items():
            with zf.open(key + ".npy", "w") as f:
                npformat.write_array(f, arr, allow_pickle=False)
    return {"samples": n, "keys": [k for k, _, _ in series]}


SCENARIOS: dict[str, Callable[..., Scenario]] = {
    "healthy": HealthyMotor,
    "faulty": FaultyMotor,
    "degrading": DegradingMotor,
    "spikes": SpikesScenario,
    "whirl": WhirlRunUp,
    "close_orders": CloseOrdersRunUp,
}

# seed 002: a microphone beside (or instead of) the accelerometer; firmware_sim.microphone
# imports this module, so it is imported once everything above exists
from .microphone import (  # noqa: E402
    DegradingMicMotor,
    DegradingMicOnlyMotor,
    FaultyMicMotor,
    HealthyMicMotor,
)

SCENARIOS.update({
    "healthy_mic": HealthyMicMotor,
    "faulty_mic": FaultyMicMotor,
    "degrading_mic": DegradingMicMotor,
    "degrading_mic_only": DegradingMicOnlyMotor,
})


def _accepted_params(factory: Callable[..., Scenario]) -> list[str]:
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


def make_scenario(name: str, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                  **params: Any) -> Scenario:
    """Build scenario ``name``; unknown names and parameters raise ValueError listing the valid ones."""
    factory = SCENARIOS.get(name)
    if factory is None:
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    accepted = _accepted_params(factory)
    bad = [p for p in params if p not in accepted]
    if bad:
        raise ValueError(f"scenario {name!r} has no parameter {', '.join(map(repr, bad))}; "
                         f"accepted: {', '.join(a for a in accepted if a not in ('n_channels', 'duration_s', 'seed'))}")
    return factory(n_channels=n_channels, duration_s=duration_s, seed=seed, **params)
