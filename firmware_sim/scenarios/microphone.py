"""A microphone beside the machine: machine sound radiated by its vibration, plus background noise.

Owns the sound models of the simulated board's microphone channel (Orimoto,
Ikuta & Wang): what a microphone a short distance from the motor of
:class:`~firmware_sim.scenarios.motor.MotorScenario` hears, in pascal, sampled at
the board's 25 kHz like any other channel (RAW mode: the daemon computes the
block energy; RMS mode: the board sends the block RMS, whose square is the
same energy).

Sound pressure at the microphone::

    p(t) = p_m(t) + p_b(t)                  machine sound + background (energies add, eq. 1)

Machine sound p_m (:class:`MachineSound`): the housing radiates its vibration.
With m(t) the machine's acceleration at the accelerometer's position (the
scenario's vibration without the accelerometer's own sensor noise) and e(t)
its running RMS over ``env_s`` (5 ms, centred)::

    p_m(t) = kappa (e(t - d) / e_ref)^(gamma - 1) m(t - d) + own_pa w_own(t)

a radiation efficiency that grows with the vibration level (``gamma`` = 1.3:
the block sound energy goes as the vibration energy to the power gamma, a
smooth nonlinear relation the daemon is not told), the propagation delay
d = ``distance_m`` / 343 m/s, and the machine's own airborne noise (cooling
fan: white, ``own_pa`` RMS) that carries no vibration information.  The
bearing impacts of a faulty motor are heard like they are felt.

Background p_b (:class:`BackgroundNoise`): sources that add in energy, none
of them Gaussian in level, all slowly varying:

* a ventilation fan: low-passed noise (``fan_fc``) at ``fan_pa`` RMS with a
  log-normal level wander (``fan_wander`` std, knots every 2 s);
* another machine switching on and off: hum (100, 200, 300 Hz) and low-passed
  noise at ``other_pa`` RMS while on, on at each 4-s knot with probability
  ``other_on``, smooth (cubic B-spline) transitions;
* road traffic: vehicle passes at ``road_per_min`` a minute (Poisson), each a
  Gaussian energy envelope of ``road_tau_s`` with a log-normal peak
  (median ``road_pa``, log-std 0.5) on low-passed rumble (``road_fc``);
* bursts (door slams, a dropped tool), off by default: ``bursts_per_min`` a
  minute, broadband, peak ``burst_pa`` (log-normal, log-std 0.5), decaying in
  ``burst_tau_s``.  One such burst outweighs minutes of background in <v^2>,
  which the paper's model needs: the unit tests use them, the normal scenarios
  do not.

Default levels: the healthy motor's sound ~76 dB SPL (0.14 Pa RMS) at the
microphone over a ~69 dB workshop background; the faulty motor ~18 dB louder.

Determinism and chunk invariance follow :mod:`firmware_sim.scenarios.base`: every
random draw belongs to a fixed time slot (a 1-s segment, a knot, a 10-s event
slot) and comes from ``SeedSequence([seed, stream, slot])`` with streams of
their own (``MIC_STREAMS``), so the microphone is the same whichever channel
carries it and however the samples are requested; the filters' memory is
replayed from the previous segment's draws.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from .base import FULL_SCALE_MS2, keyword_params
from .iir import lfilter
from .motor import DegradingMotor, FaultyMotor, HealthyMotor, MotorScenario
from .noise import MACHINE_STREAM, SlotDraws, cubic_bspline, gauss, generator

__all__ = [
    "MIC_STREAMS",
    "SOUND_SPEED",
    "MIC_FULL_SCALE_PA",
    "MachineSound",
    "BackgroundNoise",
    "MicMotorMixin",
    "HealthyMicMotor",
    "FaultyMicMotor",
    "DegradingMicMotor",
    "DegradingMicOnlyMotor",
]

#: random streams of the microphone (distinct from channels 0..8, the machine
#: (MACHINE_STREAM) and the tacho (MACHINE_STREAM + 1))
MIC_STREAMS = {name: MACHINE_STREAM + 32 + i for i, name in enumerate(
    ("own", "fan", "fan_knots", "other", "other_knots", "road", "road_events", "burst",
     "burst_events"))}
SOUND_SPEED = 343.0  # m/s
#: microphone preamplifier range: +-20 Pa (120 dB SPL peak) over the 12-bit ADC
MIC_FULL_SCALE_PA = 20.0

_EVENT_SLOT_S = 10.0
_CACHE = 24


def _one_pole(fc: float, fs: int) -> tuple[float, float]:
    """(rho, unit-variance gain) of y[n] = (1 - rho) x[n] + rho y[n-1]."""
    rho = math.exp(-2.0 * math.pi * fc / fs)
    return rho, math.sqrt((1.0 + rho) / (1.0 - rho))


class MachineSound:
    """p_m of the module docstring, from the machine's acceleration."""

    def __init__(self, *, fs: int, kappa: float, gamma: float, e_ref: float, env_s: float,
                 distance_m: float, own_pa: float):
        for key, val in dict(sound_kappa=kappa, sound_gamma=gamma, sound_e_ref=e_ref,
                             sound_env_s=env_s).items():
            if not (val > 0 and math.isfinite(val)):
                raise ValueError(f"{key} must be > 0, got {val!r}")
        for key, val in dict(distance_m=distance_m, own_pa=own_pa).items():
            if not (val >= 0 and math.isfinite(val)):
                raise ValueError(f"{key} must be >= 0, got {val!r}")
        self.fs = fs
        self.kappa, self.gamma, self.e_ref = float(kappa), float(gamma), float(e_ref)
        self.env_n = max(1, int(round(env_s * fs)))
        self.delay = int(round(distance_m / SOUND_SPEED * fs))
        self.own_pa = float(own_pa)
        self.margin = self.env_n // 2 + 1 + self.delay
        if self.margin >= fs:
            raise ValueError("sound_env_s and distance_m reach beyond one segment")

    def render(self, k: int, machine_prev: np.ndarray, machine: np.ndarray, machine_next: np.ndarray,
               draws: SlotDraws) -> np.ndarray:
        """p_m over 1-s segment k (Pa) from the machine acceleration of segments k-1, k, k+1."""
        L = machine.size
        M = self.margin
        ext = np.concatenate([machine_prev[L - M:], machine, machine_next[:M]])   # index 0 = kL - M
        # running mean square over env_n samples, centred: cumulative sums
        h = self.env_n // 2
        c = np.concatenate([[0.0], np.cumsum(ext * ext)])
        i = np.arange(M - self.delay, M - self.delay + L)       # the delayed sample of each output
        lo, hi = i - h, i - h + self.env_n
        ms = (c[hi] - c[lo]) / self.env_n
        e = np.sqrt(np.maximum(ms, 0.0))
        gain = self.kappa * (np.maximum(e, 1e-9) / self.e_ref) ** (self.gamma - 1.0)
        out = gain * ext[i]
        if self.own_pa:
            out += self.own_pa * gauss(generator(draws.seed, MIC_STREAMS["own"], k), L)
        return out


class BackgroundNoise:
    """p_b of the module docstring."""

    def __init__(self, *, fs: int, fan_pa: float, fan_fc: float, fan_wander: float,
                 other_pa: float, other_on: float, road_pa: float, road_per_min: float,
                 road_tau_s: float, road_fc: float, burst_pa: float, bursts_per_min: float,
                 burst_tau_s: float):
        vals = dict(fan_pa=fan_pa, fan_wander=fan_wander, other_pa=other_pa, road_pa=road_pa,
                    road_per_min=road_per_min, burst_pa=burst_pa, bursts_per_min=bursts_per_min)
        for key, val in vals.items():
            if not (val >= 0 and math.isfinite(val)):
                raise ValueError(f"{key} must be >= 0, got {val!r}")
        for key, val in dict(fan_fc=fan_fc, road_fc=road_fc, road_tau_s=road_tau_s,
                             burst_tau_s=burst_tau_s).items():
            if not (val > 0 and math.isfinite(val)):
                raise ValueError(f"{key} must be > 0, got {val!r}")
        if not 0.0 <= other_on <= 1.0:
            raise ValueError(f"other_on must be a probability in [0, 1], got {other_on!r}")
        if not (fan_fc < fs / 2 and road_fc < fs / 2):
            raise ValueError("fan_fc and road_fc must be below fs/2")
        if road_tau_s > 3.0:
            raise ValueError(f"road_tau_s must be <= 3 s, got {road_tau_s!r}")
        self.fs = fs
        self.fan_pa, self.fan_wander = float(fan_pa), float(fan_wander)
        self.other_pa, self.other_on = float(other_pa), float(other_on)
        self.road_pa, self.road_rate, self.road_tau = float(road_pa), float(road_per_min) / 60.0, float(road_tau_s)
        self.burst_pa, self.burst_rate, self.burst_tau = float(burst_pa), float(bursts_per_min) / 60.0, \
            float(burst_tau_s)
        self.fan_rho, self.fan_g = _one_pole(fan_fc, fs)
        self.road_rho, self.road_g = _one_pole(road_fc, fs)
        self.other_rho, self.other_g = _one_pole(400.0, fs)
        # samples of filter memory replayed from the previous segment (e^-25 of the slowest pole)
        rho = max(self.fan_rho, self.road_rho, self.other_rho)
        self.warmup = int(math.ceil(25.0 / -math.log(rho)))
        if self.warmup >= fs:
            raise ValueError("fan_fc/road_fc too low: the filters ring longer than a segment")
        self._phases: np.ndarray | None = None

    # -- carriers: unit-RMS noises, low-passed with the previous segment's memory --
    def _lowpassed(self, draws: SlotDraws, stream: str, k: int, rho: float, g: float, L: int) -> np.ndarray:
        W = self.warmup
        cur = gauss(generator(draws.seed, MIC_STREAMS[stream], k), L)
        prev = gauss(generator(draws.seed, MIC_STREAMS[stream], k - 1), L)[L - W:] if k > 0 else np.zeros(W)
        u = np.concatenate([prev, cur])
        return g * lfilter([1.0 - rho], [1.0, -rho], u)[W:]

    # -- levels -------------------------------------------------------------------
    @staticmethod
    def _spline(t: np.ndarray, dt: float, knot) -> np.ndarray:
        """Cubic B-spline through per-knot values knot(j) on the grid j * dt."""
        j0 = int(math.floor(t[0] / dt)) - 1
        j1 = int(math.floor(t[-1] / dt)) + 2
        out = np.zeros(t.size)
        for j in range(j0, j1 + 1):
            out += knot(j) * cubic_bspline(t / dt - j)
        return out

    def _events(self, draws: SlotDraws, stream: str, rate: float, t_lo: float, t_hi: float):
        """(times, log-normal factors) of the Poisson events with times in [t_lo, t_hi)."""
        s0 = int(math.floor(t_lo / _EVENT_SLOT_S))
        s1 = int(math.floor(t_hi / _EVENT_SLOT_S))
        ts, amps = [], []
        for s in range(max(s0, 0), s1 + 1):
            def make(rng, s=s):
                n = rng.poisson(rate * _EVENT_SLOT_S)
                return (s + rng.random(n)) * _EVENT_SLOT_S, np.exp(0.5 * rng.standard_normal(n))
            t, a = draws.get(MIC_STREAMS[stream], s, make)
            ts.append(t)
            amps.append(a)
        t = np.concatenate(ts) if ts else np.empty(0)
        a = np.concatenate(amps) if amps else np.empty(0)
        sel = (t >= t_lo) & (t < t_hi)
        return t[sel], a[sel]

    def render(self, k: int, draws: SlotDraws) -> np.ndarray:
        """p_b over 1-s segment k (Pa)."""
        fs = self.fs
        L = fs
        t = k + np.arange(L) / fs
        out = np.zeros(L)
        seed = draws.seed
        if self.fan_pa:
            def fan_knot(j):
                return float(generator(seed, MIC_STREAMS["fan_knots"], j + (1 << 20)).standard_normal())
            level = self.fan_pa * np.exp(self.fan_wander * self._spline(t, 2.0, fan_knot)
                                         - 0.5 * self.fan_wander ** 2)
            out += level * self._lowpassed(draws, "fan", k, self.fan_rho, self.fan_g, L)
        if self.other_pa:
            def other_knot(j):
                u = generator(seed, MIC_STREAMS["other_knots"], j + (1 << 20)).random()
                return 1.0 if u < self.other_on else 0.0
            on = np.clip(self._spline(t, 4.0, other_knot), 0.0, 1.0)
            if on.any():
                if self._phases is None:
                    self._phases = generator(seed, MIC_STREAMS["other"], 1 << 30).uniform(0, 2 * np.pi, 3)
                hum = sum(math.sqrt(2.0) * w * np.cos(2 * np.pi * f * t + ph)
                          for f, w, ph in zip((100.0, 200.0, 300.0), (0.6, 0.4, 0.3), self._phases))
                noise = self._lowpassed(draws, "other", k, self.other_rho, self.other_g, L)
                carrier = (hum + 0.6 * noise) / math.sqrt(0.36 + 0.16 + 0.09 + 0.36)
                out += self.other_pa * np.sqrt(on) * carrier
        if self.road_pa and self.road_rate:
            reach = 4.0 * self.road_tau
            tv, av = self._events(draws, "road_events", self.road_rate, k - reach, k + 1 + reach)
            if tv.size:
                energy = np.zeros(L)
                for t0, a in zip(tv, av):
                    energy += (self.road_pa * a) ** 2 * np.exp(-(((t - t0) / self.road_tau) ** 2))
                out += np.sqrt(energy) * self._lowpassed(draws, "road", k, self.road_rho, self.road_g, L)
        if self.burst_pa and self.burst_rate:
            reach = 30.0 * self.burst_tau
            tb, ab = self._events(draws, "burst_events", self.burst_rate, k - reach, k + 1)
            if tb.size:
                env = np.zeros(L)
                for t0, a in zip(tb, ab):
                    after = t >= t0
                    env[after] += self.burst_pa * a * np.exp(-(t[after] - t0) / self.burst_tau)
                out += env * gauss(generator(seed, MIC_STREAMS["burst"], k), L)
        return out


class MicMotorMixin(MotorScenario):
    """A motor scenario whose channel ``mic_channel`` is a microphone (Pa) instead of an accelerometer.

    The other channels are the motor's accelerometers, unchanged.  The
    microphone hears :class:`MachineSound` of the motor's vibration and
    :class:`BackgroundNoise`.  ``machine_off=True`` stops the machine (no
    vibration, no machine sound: the accelerometers read their sensor noise,
    the microphone the background alone), for the background stretch of a
    calibration.  ``mic_channel`` >= n_channels means the board does not carry
    the microphone.  ``board_scale`` gives the STATUS scale per channel (m/s^2
    per count, Pa per count for the microphone).

    It comes first in the bases of a concrete motor scenario (``_motor_class``, also the
    class of the noise-free twin whose vibration the microphone hears).
    """

    _motor_class: type[MotorScenario]

    def __init__(self, *, mic_channel: int = 1, machine_off: bool = False,
                 sound_kappa: float = 0.2, sound_gamma: float = 1.3, sound_e_ref: float = 0.7,
                 sound_env_s: float = 0.005, distance_m: float = 0.5, own_pa: float = 0.03,
                 fan_pa: float = 0.05, fan_fc: float = 1500.0, fan_wander: float = 0.15,
                 other_pa: float = 0.04, other_on: float = 0.4, road_pa: float = 0.05,
                 road_per_min: float = 2.0, road_tau_s: float = 1.5, road_fc: float = 300.0,
                 burst_pa: float = 0.4, bursts_per_min: float = 0.0, burst_tau_s: float = 0.03,
                 **kwargs):
        super().__init__(**kwargs)
        if not isinstance(mic_channel, (int, np.integer)) or mic_channel < 0:
            raise ValueError(f"mic_channel must be a channel index >= 0, got {mic_channel!r}")
        self.mic_channel = int(mic_channel)
        self.machine_off = bool(machine_off)
        self.sound_kappa, self.sound_gamma, self.sound_e_ref = float(sound_kappa), float(sound_gamma), \
            float(sound_e_ref)
        self.sound_env_s, self.distance_m, self.own_pa = float(sound_env_s), float(distance_m), float(own_pa)
        self.fan_pa, self.fan_fc, self.fan_wander = float(fan_pa), float(fan_fc), float(fan_wander)
        self.other_pa, self.other_on = float(other_pa), float(other_on)
        self.road_pa, self.road_per_min, self.road_tau_s, self.road_fc = float(road_pa), \
            float(road_per_min), float(road_tau_s), float(road_fc)
        self.burst_pa, self.bursts_per_min, self.burst_tau_s = float(burst_pa), float(bursts_per_min), \
            float(burst_tau_s)
        self.sound = MachineSound(fs=self.fs, kappa=sound_kappa, gamma=sound_gamma, e_ref=sound_e_ref,
                                  env_s=sound_env_s, distance_m=distance_m, own_pa=own_pa)
        self.background = BackgroundNoise(fs=self.fs, fan_pa=fan_pa, fan_fc=fan_fc, fan_wander=fan_wander,
                                          other_pa=other_pa, other_on=other_on, road_pa=road_pa,
                                          road_per_min=road_per_min, road_tau_s=road_tau_s,
                                          road_fc=road_fc, burst_pa=burst_pa,
                                          bursts_per_min=bursts_per_min, burst_tau_s=burst_tau_s)
        self._mic_draws = SlotDraws(self.seed, _CACHE)
        self._parts: OrderedDict[int, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self.board_scale = tuple(
            (MIC_FULL_SCALE_PA if c == self.mic_channel else FULL_SCALE_MS2) * 2 / 4096.0
            for c in range(self.n_channels))

    # the machine's acceleration without sensor noise: channel 0 of the noise-free twin
    def _machine(self, k: int) -> np.ndarray:
        if k < 0:
            return np.zeros(self.segment_len)
        twin = self.__dict__.get("_twin")
        if twin is None:
            motor_params = keyword_params(self._motor_class)
            params = {key: val for key, val in self.params.items()
                      if key in motor_params and key not in ("n_channels", "channel_gains")}
            params.update(n_channels=1, channel_gains=(1.0,), noise_rms=0.0)
            twin = self._twin = self._motor_class(**params)
        return twin._segment(k)[0]

    def mic_parts(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(machine sound p_m, background p_b) of 1-s segment k, Pa (the truth of the bench)."""
        got = self._parts.get(k)
        if got is None:
            L = self.segment_len
            if self.machine_off:
                pm = np.zeros(L)
            else:
                pm = self.sound.render(k, self._machine(k - 1), self._machine(k), self._machine(k + 1),
                                       self._mic_draws)
            pb = self.background.render(k, self._mic_draws)
            got = (pm, pb)
            self._parts[k] = got
            while len(self._parts) > 3:
                self._parts.popitem(last=False)
        return got

    def sound_energy(self, n_blocks: int, block_len: int = 250, start_block: int = 0) -> dict[str, np.ndarray]:
        """Per-block mean-square machine sound y_k and background v_k [Pa^2] (truth)."""
        L = self.segment_len
        if L % block_len:
            raise ValueError(f"block_len must divide {L}")
        nb = L // block_len
        ys, vs = [], []
        for k in range(start_block // nb, (start_block + n_blocks - 1) // nb + 1):
            pm, pb = self.mic_parts(k)
            ys.append(np.mean(pm.reshape(nb, block_len) ** 2, axis=1))
            vs.append(np.mean(pb.reshape(nb, block_len) ** 2, axis=1))
        off = start_block % nb
        y = np.concatenate(ys)[off:off + n_blocks]
        v = np.concatenate(vs)[off:off + n_blocks]
        return {"y": y, "v": v}

    def _render(self, k: int) -> np.ndarray:
        out = super()._render(k)
        if self.machine_off:
            machine = self._machine(k)
            for c in range(self.n_channels):
                out[c] -= self.channel_gains[c] * machine
        if self.mic_channel < self.n_channels:
            pm, pb = self.mic_parts(k)
            out[self.mic_channel] = pm + pb
        return out


class HealthyMicMotor(MicMotorMixin, HealthyMotor):
    """``healthy_mic``: the healthy motor, accelerometer on channel 0 and a microphone on channel 1."""

    name = "healthy_mic"
    description = ("healthy motor with a microphone (channel 1, Pa) beside the accelerometer "
                   "(channel 0): machine sound + fan, another machine, road traffic (Orimoto, Ikuta & Wang)")
    _motor_class = HealthyMotor


class FaultyMicMotor(MicMotorMixin, FaultyMotor):
    """``faulty_mic``: the faulty motor with the microphone on channel 1."""

    name = "faulty_mic"
    description = "faulty motor with a microphone (channel 1) beside the accelerometer (channel 0)"
    _motor_class = FaultyMotor


class DegradingMicMotor(MicMotorMixin, DegradingMotor):
    """``degrading_mic``: the degrading motor, accelerometer on channel 0, microphone on channel 1
    (run it with 2 channels, RAW or RMS mode)."""

    name = "degrading_mic"
    description = ("degrading motor (as degrading) with a microphone (channel 1) beside the "
                   "accelerometer (channel 0)")
    _motor_class = DegradingMotor


class DegradingMicOnlyMotor(MicMotorMixin, DegradingMotor):
    """``degrading_mic_only``: the degrading motor heard by a microphone alone, on channel 0
    (the same sound as ``degrading_mic``'s channel 1 for the same seed)."""

    name = "degrading_mic_only"
    description = "degrading motor heard by a microphone only (channel 0, no accelerometer)"
    _motor_class = DegradingMotor

    def __init__(self, *, mic_channel: int = 0, **kwargs):
        super().__init__(mic_channel=mic_channel, **kwargs)
