"""All indicators of one channel over one interval: a record an alarm manager can read.

:func:`compute` takes the interval's acceleration samples (m/s^2, contiguous) and
the shaft speed (or None) and returns an :class:`IndicatorRecord`: the waveform
statistics (:mod:`.statistics`), the velocity RMS and its ISO zone
(:mod:`.velocity`, :mod:`.iso_zones`), the envelope RMS and, per bearing seen by
the channel, the envelope spectrum's lines at the defect frequencies and their
second harmonics (:mod:`.envelope`, :mod:`.bearings`), and the band RMS
(:mod:`.bands`).  :meth:`IndicatorRecord.values` flattens the numbers under
stable names (``accel_rms``, ``velocity_rms_mm_s``, ``<bearing>.bpfi``,
``<bearing>.bpfi_ratio``, ``band.<name>`` ...); what cannot be computed (no speed for an order band or a
bearing) is absent, never NaN, and so is a bearing line the envelope spectrum's bins do
not resolve (:mod:`.resolution`: named in :attr:`BearingLines.unresolved`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .bands import order_band_hz
from .bearings import DefectFrequencies, Geometry, defect_frequencies
from .envelope import Envelope, LinePeak, centred_envelope_spectrum, centred_envelopes, envelope_of_rfft, line_peak
from .iso_zones import ZONES, baseline_alarm_mm_s, boundaries, zone_index
from .resolution import line_freqs, unresolved
from .spectrum import bin_range, hann_power_bins, rfft_freqs
from .statistics import WaveformStats, centred_stats, centred_stats_rows
from .velocity import velocity_band

#: a value with nothing to read (a band that holds no bin of the record's spectrum)
NAN = float("nan")

__all__ = ["Band", "Bearing", "Setup", "BearingLines", "IndicatorRecord", "compute", "compute_many"]

@dataclass(frozen=True)
class Band:
    """A band [lo, hi], in Hz or (``orders``) in multiples of the shaft speed."""

    name: str
    lo: float
    hi: float
    orders: bool = False


@dataclass(frozen=True)
class Bearing:
    name: str
    geometry: Geometry


@dataclass(frozen=True)
class Setup:
    """What :func:`compute` needs besides the samples, for one channel.

    ``velocity_band``: the configured band, or None for the ISO band of each record's speed
    (:func:`~.velocity.velocity_band`: the shaft speed given to :func:`compute`, else ``rpm``,
    the configured speed)."""

    fs: float
    velocity_band: tuple[float, float] | None
    envelope_band: tuple[float, float]
    group: int = 2
    foundation: str = "rigid"
    velocity_baseline_mm_s: float | None = None
    slip: float = 0.02
    bearings: tuple[Bearing, ...] = ()
    bands: tuple[Band, ...] = ()
    rpm: float | None = None

    def band_at(self, shaft_hz: float | None) -> tuple[float, float]:
        """The velocity band of a record at ``shaft_hz`` (None: no speed measured)."""
        speed = 60.0 * shaft_hz if shaft_hz is not None and shaft_hz > 0 else self.rpm
        return velocity_band(speed, self.velocity_band)


@dataclass
class BearingLines:
    name: str
    freqs: DefectFrequencies | None                 # Hz; None without a shaft speed
    lines: dict[str, LinePeak] = field(default_factory=dict)   # "bpfo", "bpfo_2x", ...
    #: the lines the envelope spectrum's bins do not resolve (:mod:`.resolution`): not read
    unresolved: tuple[str, ...] = ()
    #: the lines whose window reaches past the envelope spectrum (which goes up to about the
    #: envelope band's width, Randall & Antoni 2011): not read
    beyond: tuple[str, ...] = ()


@dataclass
class IndicatorRecord:
    accel: WaveformStats
    velocity_rms_mm_s: float
    velocity_band: tuple[float, float]
    zone: str                                   # "" without a velocity (its band holds no bin)
    zone_boundaries_mm_s: tuple[float, float, float]
    velocity_alarm_mm_s: float | None
    envelope_rms: float                         # NaN when the envelope band holds fewer than two bins
    envelope_band: tuple[float, float]
    shaft_hz: float | None
    bearings: list[BearingLines]
    bands: list[tuple[Band, tuple[float, float], float]]   # band, its Hz edges, RMS (NaN: no bin)

    def values(self) -> dict[str, float]:
        """Every number under a stable name (what an alarm manager compares with its levels): a
        bearing line's amplitude as ``<bearing>.<line>``, how far it stands out of the envelope
        spectrum around it (:attr:`~.envelope.LinePeak.ratio`) as ``<bearing>.<line>_ratio``."""
        out = {"accel_rms": self.accel.rms, "accel_peak": self.accel.peak,
               "crest_factor": self.accel.crest_factor, "kurtosis": self.accel.kurtosis,
               "velocity_rms_mm_s": self.velocity_rms_mm_s, "envelope_rms": self.envelope_rms,
               "zone": float(ZONES.index(self.zone)) if self.zone else NAN}
        for b in self.bearings:
            out.update({f"{b.name}.{k}": p.amplitude for k, p in b.lines.items()})
            out.update({f"{b.name}.{k}_ratio": p.ratio for k, p in b.lines.items()})
        out.update({f"band.{band.name}": rms for band, _, rms in self.bands})
        return {k: v for k, v in out.items() if v == v}


def _bearing_lines(setup: Setup, b: Bearing, shaft_hz: float | None, f: np.ndarray,
                   A: np.ndarray) -> BearingLines:
    """Bearing ``b``'s lines in the envelope spectrum (f, A) at ``shaft_hz``: each read
    (:func:`~.envelope.line_peak`) unless the spectrum's bins do not resolve it
    (:func:`~.resolution.unresolved`: then named in ``unresolved``) or its window reaches
    beyond the spectrum (an envelope band narrower than the line: named in ``beyond``)."""
    if shaft_hz is None or not shaft_hz > 0:
        return BearingLines(b.name, None)
    freqs = defect_frequencies(b.geometry, shaft_hz)
    lines = line_freqs(freqs)
    df = float(f[1] - f[0]) if f.size > 1 else 0.0
    out = BearingLines(b.name, freqs, unresolved=unresolved(lines, setup.slip, df) if df > 0 else ())
    beyond = []
    for name, f0 in lines.items():
        if name in out.unresolved:
            continue
        p = line_peak(f, A, f0, setup.slip)         # None: f0 > 0 and df > 0, so past the spectrum
        if p is None:
            beyond.append(name)
        else:
            out.lines[name] = p
    out.beyond = tuple(beyond)
    return out


def _hz_bands(setup: Setup, shaft_hz: float | None) -> list[tuple[Band, tuple[float, float]]]:
    """The bands that can be read at ``shaft_hz``, with their edges in Hz."""
    out = []
    for band in setup.bands:
        if not band.orders:
            out.append((band, (band.lo, band.hi)))
        elif shaft_hz is not None and shaft_hz > 0:
            out.append((band, order_band_hz(band.lo, band.hi, shaft_hz)))
    return out


def _spectral_sums(X: np.ndarray, N: int, f: np.ndarray, setup: Setup, vband: tuple[float, float],
                   bands: list[tuple[Band, tuple[float, float]]]) -> tuple[float, list[float]]:
    """Velocity RMS [mm/s] over ``vband`` and band RMS from the Hann power of the bins they
    read, computed once over the span of those bins (:func:`~.spectrum.hann_power_bins`); NaN
    for a band that holds no bin (narrower than the record's 1/T Hz bins: nothing to read)."""
    va, vb = _velocity_bins(N, float(setup.fs), *vband)
    ranges = [bin_range(f, *edges) for _, edges in bands]
    used = [r for r in [(va, vb)] + ranges if r[1] > r[0]]
    k0 = min((a for a, _ in used), default=0)
    P = hann_power_bins(X, N, k0, max((b for _, b in used), default=0))
    v = 1000.0 * np.sqrt((P[va - k0:vb - k0] * _velocity_weights(N, float(setup.fs), va, vb)).sum()) if vb > va else NAN
    return float(v), [float(np.sqrt(P[a - k0:b - k0].sum())) if b > a else NAN for a, b in ranges]


@lru_cache(maxsize=16)
def _velocity_bins(N: int, fs: float, lo: float, hi: float) -> tuple[int, int]:
    """The bins a..b-1 of the velocity band [lo, hi] in :func:`~.spectrum.rfft_freqs` (N, fs),
    DC left out (f > 0): found once per (N, fs, band)."""
    a, b = bin_range(rfft_freqs(N, fs), lo, hi)
    return min(max(a, 1), b), b


@lru_cache(maxsize=16)
def _velocity_weights(N: int, fs: float, a: int, b: int) -> np.ndarray:
    """1 / (2 pi f)^2 of the bins a..b-1 of :func:`~.spectrum.rfft_freqs` (N, fs) (as
    :func:`~.velocity.velocity_rms_mm_s`), read-only: computed once per (N, fs, band)."""
    w = 1.0 / (2.0 * np.pi * rfft_freqs(N, fs)[a:b]) ** 2
    w.setflags(write=False)
    return w


def compute(x: np.ndarray, setup: Setup, shaft_hz: float | None = None) -> IndicatorRecord:
    """The indicators of the contiguous record x (1-D, at least 2 samples, m/s^2, finite) at
    ``shaft_hz``.

    One real transform of the mean-removed record serves the velocity and band RMS (their
    bins of the Hann power spectrum, :func:`~.spectrum.hann_power_bins`) and the envelope
    (:func:`~.envelope.envelope_of_rfft`); the envelope spectrum is computed only when a
    bearing's lines are read.  The numbers are those of :func:`~.statistics.waveform_stats`,
    the one-sided Hann power of the whole windowed record (:mod:`.spectrum`),
    :func:`~.envelope.envelope` and :func:`~.envelope.envelope_spectrum` up to rounding
    (~1e-16 of the largest spectral bins)."""
    d = _centred(x)
    X = np.fft.rfft(d)
    env = envelope_of_rfft(X, d.size, setup.fs, setup.envelope_band)
    e = env.env
    e -= e.mean()
    return _record(d.size, X, setup, shaft_hz, centred_stats(d), env, float(np.sqrt(np.mean(e * e))))


def compute_many(items: Sequence[tuple[np.ndarray, Setup, float | None]]) -> list[IndicatorRecord]:
    """:func:`compute` of each (x, setup, shaft_hz): the same records, bit for bit, with the
    work on the records of one length done over all of them at once: their real transforms
    in one call, their waveform statistics in one pass per sum
    (:func:`~.statistics.centred_stats_rows`), and the envelopes of those with one envelope
    band in one inverse transform, centred and their RMS taken in one pass each
    (:func:`~.envelope.centred_envelopes`) (numpy's transforms cost ~0.1-0.2 ms a call on
    top of the transform itself at these lengths, a reduction ~5 us; row by row in one call
    they give the numbers of one call per row).  The records of one length are centred into
    the rows of one array (no copy to stack them)."""
    n = len(items)
    Xs: list = [None] * n                       # their real transforms
    stats: list = [None] * n                    # their waveform statistics
    envs: list = [None] * n                     # their envelopes, centred, and the RMS of each
    by_len: dict[int, list[int]] = {}
    xs = [np.asarray(x, dtype=np.float64) for x, _, _ in items]
    for i, x in enumerate(xs):
        by_len.setdefault(x.size, []).append(i)
    for N, rows in by_len.items():
        D = np.empty((len(rows), N))
        for j, i in enumerate(rows):            # _centred, into the row
            np.subtract(xs[i], xs[i].mean(), out=D[j])
        X = np.fft.rfft(D, axis=-1)
        by_band: dict[tuple[float, tuple[float, float]], list[int]] = {}
        for j, i in enumerate(rows):
            setup = items[i][1]
            by_band.setdefault((float(setup.fs), setup.envelope_band), []).append(j)
        for (fs, band), js in by_band.items():
            Xb = X if len(js) == len(rows) else X[js]
            for j, env, rms in zip(js, *centred_envelopes(Xb, N, fs, band)):
                envs[rows[j]] = (env, rms)
        for j, (i, st) in enumerate(zip(rows, centred_stats_rows(D))):
            Xs[i], stats[i] = X[j], st
    return [_record(x.size, Xi, setup, shaft_hz, st, *env)
            for x, Xi, st, env, (_, setup, shaft_hz) in zip(xs, Xs, stats, envs, items)]


def _centred(x: np.ndarray) -> np.ndarray:
    """The record minus its mean (float64, contiguous)."""
    x = np.asarray(x, dtype=np.float64)
    return x - x.mean()


def _record(N: int, X: np.ndarray, setup: Setup, shaft_hz: float | None, stats: WaveformStats,
            env: Envelope, env_rms: float) -> IndicatorRecord:
    """:func:`compute`'s record of a record of N samples from its mean-removed record's
    ``np.fft.rfft`` X, waveform statistics, envelope (:func:`~.envelope.envelope_of_rfft`)
    with its mean removed and that envelope's RMS."""
    bands = _hz_bands(setup, shaft_hz)
    vband = setup.band_at(shaft_hz)
    v, band_values = _spectral_sums(X, N, rfft_freqs(N, float(setup.fs)), setup, vband, bands)
    bounds = boundaries(setup.group, setup.foundation)
    alarm = (baseline_alarm_mm_s(setup.velocity_baseline_mm_s, setup.group, setup.foundation)
             if setup.velocity_baseline_mm_s is not None else None)
    bearings = [BearingLines(b.name, None) for b in setup.bearings]
    env_band = env.band
    if env_band[1] <= env_band[0]:              # fewer than two bins: no modulation to read
        env_rms, env_band = NAN, setup.envelope_band
    elif setup.bearings and shaft_hz is not None and shaft_hz > 0:
        fe, A = centred_envelope_spectrum(env.env, env.fs_env)
        bearings = [_bearing_lines(setup, b, shaft_hz, fe, A) for b in setup.bearings]
    top = min(vband[1], setup.fs / 2) if vband[0] < setup.fs / 2 else vband[1]   # past Nyquist: as configured
    return IndicatorRecord(stats, v, (vband[0], top),
                           ZONES[zone_index(v, setup.group, setup.foundation)] if v == v else "", bounds, alarm,
                           env_rms, env_band, shaft_hz,
                           bearings, [(band, edges, r) for (band, edges), r in zip(bands, band_values)])
