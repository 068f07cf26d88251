"""The synthetic run-ups of Yeh, Pan & Le on the simulated board: ``whirl`` and ``close_orders``.

The components come from :mod:`firmware_sim.order_signals`; their true
waveforms can be written beside a capture (:func:`~firmware_sim.scenarios.truth.write_truth`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..order_signals import RUNUPS
from .base import Scenario
from .noise import gauss, generator

__all__ = ["RunUpScenario", "WhirlRunUp", "CloseOrdersRunUp"]


class RunUpScenario(Scenario):
    """A synthetic run-up of Yeh, Pan & Le (:mod:`firmware_sim.order_signals`) on the board.

    Acceleration of channel c (gain g_c), in m/s^2 as the paper gives the
    amplitudes::

        a_c(t) = g_c * ( sum_i x_i(t) + sigma * w_c(t) ),   sigma = noise * ref_rms

    where x_i are the run-up's components (``RunUp.signals``: orders
    A(t) cos(2 pi o turns(t)) and fixed-frequency lines), evaluated at the
    sample times (k * fs + m) / fs of each 1-s segment k (so chunking never
    changes a sample), and w_c is the channel's own white Gaussian noise with
    std 1 (16-bit quantised, :func:`~firmware_sim.scenarios.noise.gauss`)
    drawn per segment from ``SeedSequence([seed, c, k])``. The noise std is
    ``noise`` (default 0.05) times the RMS of the order-1 component at its largest
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
        factory = type(self)._factory
        if factory is None:
            raise TypeError(f"{type(self).__name__}: a run-up scenario needs a _factory")
        self.runup = factory(**kwargs)
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
                np.multiply(gauss(generator(self.seed, c, k), L), self.noise_std, out=row)
                row += clean
            else:
                row[:] = clean
            row *= self.channel_gains[c]
        return out


def _runup_signal(name: str) -> Callable[..., Any]:
    def make(**kwargs):
        return RUNUPS[name](**kwargs)

    return staticmethod(make)


class WhirlRunUp(RunUpScenario):
    """``whirl``: Yeh, Pan & Le synthetic signal 1 (``order_signals.whirl_runup``).

    A journal-bearing rotor runs up 0 -> 7000 rpm in 180 s: order 1 (unbalance)
    1 -> 4 peak, order 0.47 (oil whirl) 2 -> 4 between 3000 and 6000 rpm, a
    47-Hz line (oil whip) 4 -> 6 from 6000 rpm; noise 5 % of the order-1 RMS.
    """

    name = "whirl"
    description = ("Yeh, Pan & Le signal 1: journal-bearing run-up 0 -> 7000 rpm in 180 s, order 1, "
                   "oil whirl (order 0.47, 3000-6000 rpm) and whip (47 Hz from 6000 rpm)")
    natural_duration_s = 180.0
    _factory = _runup_signal("whirl")


class CloseOrdersRunUp(RunUpScenario):
    """``close_orders``: Yeh, Pan & Le synthetic signal 2 (``order_signals.close_orders_runup``).

    Run-up 0 -> 3000 rpm in 5 s: order 1 with RMS 2, order 4 with RMS 0 -> 10
    and order 4.2 with RMS 2 -> 12 (peaks up to 17 m/s^2, inside the board's
    +-20 g range); noise 5 % of the order-1 RMS.
    """

    name = "close_orders"
    description = ("Yeh, Pan & Le signal 2: run-up 0 -> 3000 rpm in 5 s with order 1 and the close "
                   "orders 4 and 4.2 (RMS up to 12 m/s^2)")
    natural_duration_s = 5.0
    _factory = _runup_signal("close_orders")
