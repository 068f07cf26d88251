"""Microphone channels (kind: microphone): the acoustic estimator of Orimoto, Ikuta & Wang.

A microphone channel is watched through its sound: z_k = (block RMS)^2 [Pa^2]
goes through the estimator (:class:`~cmsensord.dsp.acoustic.AcousticEstimator`,
one calibrated model per channel), sqrt(x^_k) — the vibration energy's RMS
[m/s^2] — takes the place of the channel's observation in the severity chain,
and ``/cm/<channel>/vibration_estimate`` is written per block.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cmsensord.config import ChannelConfig, Config
from cmsensord.monitor import messages
from cmsensord.monitor.events import Event

if TYPE_CHECKING:
    from cmsensord.dsp.acoustic.model import AcousticModel


class Microphones:
    """The estimator of the microphone columns ``cols`` of the monitored channels."""

    def __init__(self, estimator, channels: tuple[ChannelConfig, ...], cols: list[int]):
        self.estimator = estimator
        self.channels = channels
        self.cols = cols

    @classmethod
    def create(cls, cfg: Config, channels: tuple[ChannelConfig, ...], *, fs: int, block_len: int,
               loaded: dict[str, AcousticModel] | None = None) -> tuple[Microphones | None, list[Event]]:
        """The estimator of the microphone channels among ``channels`` (None when there is
        none), and an event per calibration made with another block length. ``loaded``: the
        calibrations read before, by path: a file is read once, at the first chain that needs
        it, and a chain made again (a board reset, a new set of channels) runs on the same
        calibration, as every setting is read once; a file read now is added to it."""
        cols = [c for c, ch in enumerate(channels) if ch.kind == "microphone"]
        if not cols:
            return None, []
        from cmsensord.acoustic_model import load_calibration
        from cmsensord.dsp.acoustic import AcousticEstimator, Guards

        models, events = [], []
        block_s = block_len / fs
        for c in cols:
            ch = channels[c]
            path = str(ch.calibration or cfg.acoustic.calibration)     # the configuration checked it is set
            model = (loaded or {}).get(path) or load_calibration(path)
            if loaded is not None:
                loaded[path] = model
            if abs(model.block_s - block_s) > 1e-9:
                events.append(Event("config", ch.name, f"{ch.name}: acoustic calibration {path} was made "
                                    f"with {model.block_s * 1e3:g} ms blocks, the board sends "
                                    f"{block_s * 1e3:g} ms: the vibration estimate is biased; calibrate "
                                    "with this board setting"))
            models.append(model)
        return cls(AcousticEstimator(models, Guards(zeta_max=cfg.acoustic.zeta_max)), channels, cols), events

    def step(self, y: np.ndarray, valid: np.ndarray, stamps: list[int]) -> list[messages.Message]:
        """Microphone columns of y (T, C): block RMS [Pa] -> z = RMS^2 -> estimator -> x^ ->
        sqrt(x^) replaces them in y; the /cm/<ch>/vibration_estimate messages per block."""
        cols = self.cols
        ok = valid[:, cols]
        z = y[:, cols] ** 2
        est = self.estimator.process(z, ok)
        rms = np.sqrt(np.maximum(est.x_hat, 0.0))
        y[:, cols] = np.where(ok, rms, np.nan)
        out: list[messages.Message] = []
        for j, c in enumerate(cols):
            out += messages.vibration_estimate(self.channels[c].name, stamps, rms, z, ok, est, j)
        return out
