"""The simulator's random numbers: seeded streams, 16-bit Gaussian noise, random-knot splines.

Every random draw of the simulated board comes from a generator seeded with
``np.random.SeedSequence([seed, stream, k])``: ``seed`` is the scenario's seed,
``stream`` names what is drawn and ``k`` the time slot it belongs to (a 1-s
segment, a knot, a block of tacho pulses). Streams in use:

========================  ====================================================
0 .. 8                    channel c's own sensor noise
:data:`MACHINE_STREAM`    what the machine does (shared by all channels)
``MACHINE_STREAM + 1``    the board's tacho encoder faults (``board.TACHO_STREAM``)
``MACHINE_STREAM + 32..`` the microphone's sources (``microphone.MIC_STREAMS``)
========================  ====================================================

Slots below 0 (the pre-boot neighbour of segment 0) are seeded with
``[seed, stream, PRE_BOOT, -k]``, since SeedSequence takes no negatives.

Gaussian noise (:func:`gauss`) is an inverse-CDF lookup of 16-bit uniforms:
the 65536 mid-point quantiles of N(0, 1), rescaled to unit variance (tails
truncated at +-4.3 sigma). Four values per 64-bit PCG64 output: 4x faster than
the ziggurat here, and the bit generator's stream is stable across numpy
versions. scipy is imported only when the first noise is drawn, so the
scenarios can be listed without loading it.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["MACHINE_STREAM", "PRE_BOOT", "seed_entropy", "generator", "gauss", "gauss_table",
           "cubic_bspline", "SlotDraws"]

#: ``SeedSequence([seed, MACHINE_STREAM, k])`` seeds the machine's own draws of
#: segment k (shared by all channels); channel c's draws use ``[seed, c, k]``.
MACHINE_STREAM = 1 << 16
#: Segment indices below 0 (the pre-boot neighbour of segment 0) are seeded
#: with ``[seed, stream, PRE_BOOT, -k]``, since SeedSequence takes no negatives.
PRE_BOOT = 1 << 32


def seed_entropy(seed: int, stream: int, k: int) -> list[int]:
    """The SeedSequence entropy of slot ``k`` of ``stream`` (negative slots: see PRE_BOOT)."""
    return [seed, stream, k] if k >= 0 else [seed, stream, PRE_BOOT, -k]


def generator(seed: int, stream: int, k: int) -> np.random.Generator:
    """A PCG64 generator for slot ``k`` of ``stream`` under ``seed``."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed_entropy(seed, stream, k))))


@functools.lru_cache(maxsize=1)
def gauss_table() -> np.ndarray:
    """The 65536 standard-normal quantiles, rescaled to unit variance."""
    from scipy.special import ndtri

    table = ndtri((np.arange(65536) + 0.5) / 65536)
    return table / np.sqrt(np.mean(table**2))


def gauss(rng: np.random.Generator, n: int) -> np.ndarray:
    """n standard-normal values (quantised to 16 bits, see :func:`gauss_table`)."""
    raw = rng.bit_generator.random_raw((n + 3) // 4).astype("<u8", copy=False)
    return gauss_table().take(raw.view("<u2")[:n])


def cubic_bspline(x: np.ndarray) -> np.ndarray:
    """The cardinal cubic B-spline, centred on 0, support (-2, 2): the smooth wander
    through random knots."""
    ax = np.abs(x)
    out = np.zeros_like(ax)
    m1 = ax < 1.0
    m2 = (ax >= 1.0) & (ax < 2.0)
    out[m1] = 2.0 / 3.0 - ax[m1] ** 2 + 0.5 * ax[m1] ** 3
    out[m2] = (2.0 - ax[m2]) ** 3 / 6.0
    return out


class SlotDraws:
    """The random draws of each (stream, slot) under one seed: made once from
    :func:`generator` and kept for the ``size`` pairs requested last, so a slot's
    draws never depend on the order of the requests."""

    def __init__(self, seed: int, size: int):
        self.seed = seed
        self.size = size
        self._cache: OrderedDict[tuple[int, int], Any] = OrderedDict()

    def get(self, stream: int, slot: int, make: Callable[[np.random.Generator], Any]) -> Any:
        """``make(generator(seed, stream, slot))``, made on the first request."""
        key = (stream, slot)
        d = self._cache.get(key)
        if d is None:
            d = make(generator(self.seed, stream, slot))
            self._cache[key] = d
            while len(self._cache) > self.size:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        return d
