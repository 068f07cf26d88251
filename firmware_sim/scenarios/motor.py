"""The induction motor of Kim et al. 2023 (section IV): healthy, faulty and degrading.

A 3-phase, 4-pole, 3.7 kW induction motor at about 1720 rpm, so f_r = 28.66 Hz,
with an accelerometer on top of it; a motor is "faulty" above 7.1 mm/s velocity
RMS (ISO 10816, "unacceptable"). :class:`MotorScenario` is the physical model
with a fault-severity knob s(t); :class:`HealthyMotor`, :class:`FaultyMotor`
and :class:`DegradingMotor` choose s(t). :func:`velocity_rms` is the ISO 10816
measure the levels are given in.
"""

from __future__ import annotations

import math

import numpy as np

from .base import ConstantSpeed, Scenario
from .iir import lfilter
from .noise import MACHINE_STREAM, PRE_BOOT, cubic_bspline, gauss, generator

__all__ = ["MotorScenario", "HealthyMotor", "FaultyMotor", "DegradingMotor", "velocity_rms"]


def _smooth_ramp(u: np.ndarray) -> np.ndarray:
    """0 -> 1 over u in [0, 1] with zero slope at both ends (raised cosine)."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


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


class MotorScenario(ConstantSpeed, Scenario):
    """The induction motor of Kim et al. 2023, section IV, with a fault-severity knob s(t).

    Physical model (acceleration at the sensor, channel c with gain g_c)::

        a_c(t) = g_c * [ sum_h Re{ A_h(t) exp(j 2 pi f_h t) }
                         + R * (impacts(t) + sigma_r w_m(t)) ] + noise_rms * w_c(t)

    * rotation components h = 1x, 2x, 3x of f_r = ``shaft_hz`` (28.66 Hz: 1720
      rpm, Kim et al. 2023) and the electromagnetic 2x line component at
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

    White noise is Gaussian, quantised to 16 bits (see :func:`~firmware_sim.scenarios.noise.gauss`).

    Calibration against Kim et al. 2023 (the paper's parameters must give the
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
        self.shaft_hz_value = float(shaft_hz)
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
        self._setup_components()
        self._setup_resonance()
        self.bpfo_hz = self.bpfo_ratio * self.shaft_hz_value

    def _setup_components(self) -> None:
        """The rotation/line components: amplitudes, carrier tables, wander basis, phases."""
        L, fs = self.segment_len, self.fs
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
        self._basis = np.stack([cubic_bspline(x + 1.0 - jj) for jj in range(self._knots_per_seg + 3)])
        base = generator(self.seed, MACHINE_STREAM, PRE_BOOT + 1)  # fixed phases of the components
        self._phase0 = base.uniform(0.0, 2.0 * np.pi, H)

    def _setup_resonance(self) -> None:
        """The housing resonance R and the structure-noise gain that gives its band RMS."""
        L, fs = self.segment_len, self.fs
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
        h = lfilter(self._res_b, self._res_a, np.r_[1.0, np.zeros(self._warmup * 2)])
        self._res_noise_gain = self.resonance_noise_rms / math.sqrt(float(np.sum(h * h)))

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
        white = gauss(rng, L)
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
        machine += lfilter(self._res_b, self._res_a, u)[W:]
        out = np.empty((self.n_channels, L))
        for c in range(self.n_channels):
            row = out[c]
            np.multiply(machine, self.channel_gains[c], out=row)
            if self.noise_rms:
                row += self.noise_rms * gauss(generator(self.seed, c, k), L)
        return out


class HealthyMotor(MotorScenario):
    """``healthy``: the Kim et al. 2023 motor in good condition, s(t) = 0.

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
    """``faulty``: the Kim et al. 2023 motor above 7.1 mm/s (ISO 10816 "unacceptable"), s(t) = ``level``.

    See :class:`MotorScenario`. At ``level`` = 1 the 1x reaches 7.5 mm/s, 2x 3.3,
    3x 1.5 mm/s: about 8.3 mm/s velocity RMS, and outer-race impacts at BPFO =
    3.58 f_r = 102.6 Hz ring the 3 kHz resonance; about 2.2 m/s^2 acceleration RMS.
    """

    name = "faulty"
    description = ("the same motor with unbalance/looseness (~8.3 mm/s velocity RMS: zone D above 4.5 of the "
                   "default ISO 10816-3 group 2, rigid) and an outer-race bearing defect (impacts at BPFO = "
                   "3.58 f_r ringing at 3 kHz)")

    def __init__(self, *, level: float = 1.0, **kwargs):
        if not level >= 0:
            raise ValueError(f"level must be >= 0, got {level!r}")
        self.level = float(level)
        super().__init__(**kwargs)

    def severity(self, t) -> np.ndarray:
        return np.full(np.shape(t), self.level)


class DegradingMotor(MotorScenario):
    """``degrading``: healthy -> faulty -> worse -> easing over ``duration_s`` (Kim et al. 2023, Figs. 14-16).

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
    description = ("healthy to 25 %, then rising to faulty (at 60 %) -> 40 % worse (at 80 %) -> easing below "
                   "the faulty level by the end of --duration (Kim et al. 2023, Figs. 14-16)")

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

