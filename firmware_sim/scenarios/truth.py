"""The true waveforms of a scenario, written beside a capture as an .npz file."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .base import Scenario

__all__ = ["truth_key", "write_truth"]


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
    fs = scenario.fs
    rate = float(fs if rate is None else rate)
    _check(scenario, duration_s, rate, channel)
    n = int(math.floor(duration_s * rate + 1e-9))
    step = fs / rate
    sub = int(round(step)) if abs(step - round(step)) < 1e-9 else None
    gain = float(scenario.channel_gains[channel])
    comps_fn = getattr(scenario, "components", None)
    names = list(comps_fn(np.zeros(1))) if comps_fn is not None else []
    series = _series(scenario, rate, sub, channel, gain, names)
    meta = {
        "fs": np.array(fs), "rate": np.array(rate), "channel": np.array(channel),
        "gain": np.array(gain), "noise_std": np.array(gain * float(getattr(scenario, "noise_std", 0.0))),
        "components": np.array(names, dtype=str), "keys": np.array([truth_key(x) for x in names], dtype=str),
        "scenario": np.array(scenario.name), "seed": np.array(scenario.seed),
    }
    _write_npz(path, series, meta, n, max(1, int(chunk_s * rate)))
    return {"samples": n, "keys": [k for k, _, _ in series]}


def _check(scenario: Scenario, duration_s: float, rate: float, channel: int) -> None:
    """ValueError naming the first of ``rate``, ``channel`` and ``duration_s`` out of range."""
    fs = scenario.fs
    if not (rate > 0 and math.isfinite(rate)) or rate > fs:
        raise ValueError(f"truth rate must be in (0, fs={fs}] Hz, got {rate!r}")
    if not 0 <= channel < scenario.n_channels:
        raise ValueError(f"channel must be 0..{scenario.n_channels - 1}, got {channel}")
    if not duration_s > 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s!r}")


Series = list[tuple[str, str, Callable[[int, int], np.ndarray]]]


def _series(scenario: Scenario, rate: float, sub: int | None, channel: int, gain: float,
            names: list[str]) -> Series:
    """(key, dtype, values of truth samples a..b) of every array :func:`write_truth` streams;
    ``sub``: board samples per truth sample when whole (else None: no ``accel``); ``names``:
    the scenario's components."""
    fs = scenario.fs
    comps_fn = getattr(scenario, "components", None)

    def times(a: int, b: int) -> np.ndarray:
        if sub is not None:  # the board's own sample times, computed the way the scenario does
            return (np.arange(a, b, dtype=np.int64) * sub) / fs
        return np.arange(a, b, dtype=np.int64) / rate

    series: Series = [
        ("t", "<f8", times),
        ("rpm", "<f8", lambda a, b: 60.0 * np.asarray(scenario.shaft_hz(times(a, b)), dtype=np.float64)),
        ("turns", "<f8", lambda a, b: scenario.shaft_turns(times(a, b))),
    ]
    if comps_fn is not None:
        def component(name: str) -> Callable[[int, int], np.ndarray]:
            return lambda a, b: gain * comps_fn(times(a, b))[name]

        for name in names:
            series.append((truth_key(name), "<f4", component(name)))
    if sub is not None:
        series.append(("accel", "<f4",
                       lambda a, b: scenario.samples(a * sub, (b - a - 1) * sub + 1)[channel, ::sub]))
    return series


def _write_npz(path, series: Series, meta: dict[str, np.ndarray], n: int, chunk: int) -> None:
    """An uncompressed .npz of ``n`` values per series, each written ``chunk`` at a time
    (bounded memory), and the ``meta`` arrays."""
    import zipfile

    from numpy.lib import format as npformat

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
