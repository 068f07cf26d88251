"""Bands that hold no bin of a record's spectrum: their values left out, listed unavailable, said once.

A record of T s has spectral bins 1/T Hz apart (1 Hz at the default ``indicators.interval_s``,
10 Hz for a capture of 0.1-s snapshots).  A band narrower than that may hold no bin at all: the
velocity band, the envelope band, a band of ``indicators.bands`` (one in orders narrows with
the speed).  Its value has nothing to read (it would read 0: a velocity of 0 mm/s, zone A, on
a machine in zone D).  An envelope band of one bin has nothing to read either: a single bin is
one tone, whose envelope (the analytic signal's magnitude) is a constant, so its envelope RMS
read 0 under a bearing's impacts of 1 g.  The record leaves such a value out and names it in ``unavailable``
(:func:`~cmsensord.monitor.indicators.without_dead`, as for a band past Nyquist), and one
``band_too_narrow`` warning per channel, band and bin width says which band and what would do.
"""

from __future__ import annotations

import math

from cmsensord.dsp.indicators import IndicatorRecord, Setup
from cmsensord.monitor.events import Event

__all__ = ["empty_bands", "empty_band_events"]

#: (the band's configuration key, its [lo, hi] Hz in the record, the values it leaves unavailable)
EmptyBand = tuple[str, tuple[float, float], tuple[str, ...]]
#: the envelope band's configuration key
ENVELOPE_KEY = "indicators.envelope_band_hz"


def empty_bands(r: IndicatorRecord, setup: Setup) -> list[EmptyBand]:
    """The bands of record ``r`` (of ``setup``) that held no bin, the envelope band fewer than two
    (their values NaN), but those
    in Hz at or past the Nyquist frequency (said once at the start:
    :func:`~cmsensord.monitor.indicators.above_nyquist`); a band in orders is there at any speed."""
    half = setup.fs / 2.0
    out: list[EmptyBand] = []
    if r.velocity_rms_mm_s != r.velocity_rms_mm_s and r.velocity_band[0] < half:
        out.append(("indicators.velocity_band_hz", r.velocity_band, ("velocity_rms_mm_s", "zone")))
    if r.envelope_rms != r.envelope_rms and r.envelope_band[0] < half:
        out.append((ENVELOPE_KEY, r.envelope_band, ("envelope_rms", "bearings")))
    index = {b.name: i for i, b in enumerate(setup.bands)}
    for band, edges, rms in r.bands:
        if rms != rms and (edges[0] < half or band.orders):
            unit = f", {band.lo:g}-{band.hi:g} orders" if band.orders else ""
            out.append((f"indicators.bands[{index[band.name]}] ({band.name}{unit})", edges, (f"band.{band.name}",)))
    return out


def empty_band_events(channel: str, empty: list[EmptyBand], record_s: float, fs: float, stamp: int,
                      told: set) -> list[Event]:
    """A ``band_too_narrow`` warning for each of the ``empty`` bands of a record of ``record_s``
    seconds of ``channel`` not said yet at that bin width (the envelope band's of one bin says
    that its envelope is a constant) (``told``: what was said); a
    ``band_above_nyquist`` warning, once per channel and band, for one at or past ``fs`` / 2
    (a band in orders at a high speed)."""
    df = 1.0 / record_s
    out = []
    for key, (lo, hi), names in empty:
        told_as = (channel, key, "nyquist" if lo >= fs / 2 else round(df, 9))
        if told_as in told:
            continue
        told.add(told_as)
        bins = math.floor(hi * record_s) - math.ceil(lo * record_s) + 1     # as the envelope counts them
        if key == ENVELOPE_KEY and bins == 1:
            out.append(Event("band_too_narrow", channel, (
                f"{channel}: {key} {lo:g}-{hi:g} Hz holds one bin of the record's spectrum ({df:g}-Hz bins, "
                f"records of {record_s:g} s), a single tone whose envelope is a constant: {', '.join(names)} "
                f"listed unavailable; widen the band to at least {2 * df:g} Hz (wider than the bearing lines "
                "to read), or lengthen indicators.interval_s"), stamp,
                {"details": {"band": key, "bin_hz": round(df, 9)}}))
            continue
        if lo >= fs / 2:
            out.append(Event("band_above_nyquist", channel, (
                f"{channel}: {key} {lo:g}-{hi:g} Hz at this speed: at or above the Nyquist frequency "
                f"{fs / 2:g} Hz of the board's {fs:g} Hz sampling, no signal there: {', '.join(names)} "
                "listed unavailable while it is; set the band's orders lower"), stamp,
                {"details": {"band": key}}))
            continue
        out.append(Event("band_too_narrow", channel, (
            f"{channel}: {key} {lo:g}-{hi:g} Hz holds no bin of the record's spectrum ({df:g}-Hz bins, "
            f"records of {record_s:g} s): {', '.join(names)} listed unavailable; widen the band to at "
            f"least {df:g} Hz, or lengthen indicators.interval_s"), stamp,
            {"details": {"band": key, "bin_hz": round(df, 9)}}))
    return out
