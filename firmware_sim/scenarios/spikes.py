"""The illustrative spike input of Kim et al. 2023, Fig. 4, at the observation level."""

from __future__ import annotations

import numpy as np

from .base import ConstantSpeed, Scenario
from .noise import MACHINE_STREAM, gauss, generator

__all__ = ["SpikesScenario"]


class SpikesScenario(ConstantSpeed, Scenario):
    """``spikes``: the illustrative input of Kim et al. 2023, Fig. 4, at the observation level.

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
    ``shaft_hz`` (28.66 Hz) is nominal: the signal has no rotational content.
    """

    name = "spikes"
    description = ("Kim et al. 2023 Fig. 4: random 100 Hz RMS sequence (base ~1 m/s^2) with 25 "
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
            w = gauss(generator(self.seed, c, k), self.segment_len)
            np.multiply(w.reshape(nb, bl), (self.channel_gains[c] * level)[:, None],
                        out=out[c].reshape(nb, bl))
        return out
