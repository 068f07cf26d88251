"""The synthetic validation signals of Yeh, Pan & Le, section 4.1, at any rate.

Both are linear run-ups whose components are known exactly, so they are the
ground truth for the order tracker, the batch VKF, the simulator's `whirl` and
`close_orders` scenarios, and the benchmarks.  Everything is an analytic
function of time, so any sample range can be evaluated on its own (the
simulator generates 1-s segments; tests take the whole record at 2 kHz).

Signal 1, ``whirl`` (journal-bearing rotor, oil whirl and whip): the rotor runs
up from 0 to 7000 rpm in 180 s.  Order 1 (unbalance) grows in amplitude from 1
to 4 over the run-up; order 0.47 (oil whirl) exists from 3000 rpm (amplitude 2)
to 6000 rpm (amplitude 4); a fixed 47-Hz component (oil whip, the first bending
mode) appears at 6000 rpm, where order 0.47 is exactly 47 Hz, with amplitude
growing from 4 to 6 at 7000 rpm.  The paper says "amplitude" for these, so they
are peak amplitudes.

Signal 2, ``close_orders`` (multifunction transmission): 0 to 3000 rpm in 5 s;
order 1 with RMS 2 throughout, order 4 with RMS rising linearly 0 -> 10 and
order 4.2 with RMS 2 -> 12 (the paper gives RMS values here).

Components are ``A(t) cos(2 pi o turns(t))`` for an order o (turns = shaft
revolutions since t = 0) and ``A(t) cos(2 pi f (t - t_on))`` for a fixed
frequency f switched on at t_on.  After the run-up the speed stays at its top
value and the amplitudes at their end values.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Component", "RunUp", "OrderSignal", "whirl_runup", "close_orders_runup",
           "whirl", "close_orders", "RUNUPS"]


@dataclass(frozen=True)
class Component:
    """One order (``order`` set) or fixed-frequency (``freq_hz`` set) component.

    Its peak amplitude is linear in shaft speed between ``rpm_on`` (amplitude
    ``amp_on``) and ``rpm_off`` (``amp_off``); zero outside [rpm_on, rpm_off).
    """

    name: str
    amp_on: float
    amp_off: float
    rpm_on: float = 0.0
    rpm_off: float = float("inf")
    order: float | None = None
    freq_hz: float | None = None


@dataclass(frozen=True)
class RunUp:
    """A linear run-up 0 -> ``rpm_max`` in ``duration_s``, then constant speed."""

    name: str
    rpm_max: float
    duration_s: float
    components: tuple[Component, ...]
    ref_component: str = field(default="")   # the component noise is relative to

    @property
    def accel_rpm_per_s(self) -> float:
        return self.rpm_max / self.duration_s

    def rpm(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        return np.minimum(t, self.duration_s) * self.accel_rpm_per_s

    def turns(self, t) -> np.ndarray:
        """Shaft revolutions since t = 0 (the exact integral of rpm/60)."""
        t = np.asarray(t, dtype=np.float64)
        a = self.accel_rpm_per_s / 60.0                      # rev/s^2
        tc = np.minimum(t, self.duration_s)
        return 0.5 * a * tc * tc + np.maximum(t - self.duration_s, 0.0) * self.rpm_max / 60.0

    def time_at_rpm(self, rpm: float) -> float:
        return min(rpm, self.rpm_max) / self.accel_rpm_per_s

    def amplitude(self, comp: Component, t) -> np.ndarray:
        rpm = self.rpm(t)
        top = min(comp.rpm_off, self.rpm_max)
        span = max(top - comp.rpm_on, 1e-12)
        frac = np.clip((rpm - comp.rpm_on) / span, 0.0, 1.0)
        a = comp.amp_on + (comp.amp_off - comp.amp_on) * frac
        on = (rpm >= comp.rpm_on) & (rpm < comp.rpm_off)
        return np.where(on, a, 0.0)

    def component(self, comp: Component, t) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        if comp.order is not None:
            phase = 2 * np.pi * comp.order * self.turns(t)
        elif comp.freq_hz is not None:
            t_on = self.time_at_rpm(comp.rpm_on)
            phase = 2 * np.pi * comp.freq_hz * (t - t_on)
        else:
            raise ValueError(f"{comp.name}: a component needs an order or a frequency")
        return self.amplitude(comp, t) * np.cos(phase)

    def signals(self, t) -> dict[str, np.ndarray]:
        """Every component's waveform at times t [s]."""
        return {c.name: self.component(c, t) for c in self.components}

    def clean(self, t) -> np.ndarray:
        return np.asarray(sum(self.signals(t).values()))

    def ref_rms(self) -> float:
        """RMS of the reference component at its largest (noise is relative to it)."""
        c = next(c for c in self.components if c.name == self.ref_component)
        return max(c.amp_on, c.amp_off) / np.sqrt(2.0)


def whirl_runup(duration_s: float = 180.0, rpm_max: float = 7000.0) -> RunUp:
    """Yeh, Pan & Le synthetic signal 1 (scaled in time by ``duration_s``)."""
    return RunUp("whirl", rpm_max, duration_s, (
        Component("order 1", 1.0, 4.0, order=1.0),
        Component("order 0.47", 2.0, 4.0, rpm_on=3000.0, rpm_off=6000.0, order=0.47),
        Component("47 Hz", 4.0, 6.0, rpm_on=6000.0, freq_hz=47.0),
    ), ref_component="order 1")


def close_orders_runup(duration_s: float = 5.0, rpm_max: float = 3000.0) -> RunUp:
    """Yeh, Pan & Le synthetic signal 2: RMS 2, 0 -> 10 and 2 -> 12 (peak = RMS * sqrt 2)."""
    s = np.sqrt(2.0)
    return RunUp("close_orders", rpm_max, duration_s, (
        Component("order 1", 2.0 * s, 2.0 * s, order=1.0),
        Component("order 4", 0.0, 10.0 * s, order=4.0),
        Component("order 4.2", 2.0 * s, 12.0 * s, order=4.2),
    ), ref_component="order 1")


RUNUPS = {"whirl": whirl_runup, "close_orders": close_orders_runup}


@dataclass
class OrderSignal:
    """A whole record: time, speed, the measured signal and its true components."""

    fs: float
    t: np.ndarray
    rpm: np.ndarray
    turns: np.ndarray
    y: np.ndarray                        # sum of the components + white noise
    components: dict[str, np.ndarray]
    runup: RunUp
    noise_std: float


def _record(runup: RunUp, fs: float, noise: float, seed: int, duration_s: float | None) -> OrderSignal:
    n = int(round((duration_s if duration_s is not None else runup.duration_s) * fs))
    t = np.arange(n) / fs
    comps = runup.signals(t)
    std = noise * runup.ref_rms()
    y = sum(comps.values()) + std * np.random.default_rng(seed).standard_normal(n)
    return OrderSignal(fs, t, runup.rpm(t), runup.turns(t), y, comps, runup, std)


def whirl(fs: float = 2000.0, *, noise: float = 0.0, seed: int = 0,
          duration_s: float | None = None) -> OrderSignal:
    """Signal 1 sampled at ``fs``; ``noise`` = white-noise std relative to the order-1 RMS."""
    return _record(whirl_runup(), fs, noise, seed, duration_s)


def close_orders(fs: float = 2000.0, *, noise: float = 0.05, seed: int = 0,
                 duration_s: float | None = None) -> OrderSignal:
    """Signal 2 sampled at ``fs``, with white noise of std ``noise`` x the order-1 RMS
    (5 % by default, the noise level of Yeh, Pan & Le's section 5)."""
    return _record(close_orders_runup(), fs, noise, seed, duration_s)
