"""Each channel's mean taken out of an imported recording, as the board's offset calibration
takes it out of its own signal.

The board subtracts a calibrated fixed offset from every sample, so its RMS and RAW counts
carry the vibration about zero (docs/PROTOCOL.md: the RMS of the offset-corrected block). A
DC-coupled logger's recording carries its amplifier's and sensor's offset instead (the IMS
rig's first test: a mean of -0.095 g against 0.081 g RMS of vibration), which would go into
every block RMS and the severity's level (a vibration that grows 2.5 x would read a level
1.8 x the baseline) and take up the 12-bit range (a coarser count for the vibration).
:func:`remove_dc` measures each channel's mean and the recording's peak without it (the
full-scale range is then chosen from the vibration alone); the capture writer subtracts the
means before the samples become counts.

Where the mean is taken:

* a recording of several snapshots (files, or ``--snapshot-len`` pieces): each snapshot's
  own, since each is its own acquisition (a logger's offset moves between files hours apart,
  as an offset calibrated at each start would);
* one continuous recording: its whole length's, one constant per channel, as the board
  subtracts one fixed offset. A running mean would be a high-pass filter the board does not
  have: it would also take out the slow part of a run-up or of a level that changes over
  minutes, which the board keeps.

Missing samples (NaN) are left out of the means and stay missing. A microphone's channel
(Pa) is treated alike: its offset is no sound pressure either.
"""

from __future__ import annotations

import numpy as np

from .recording import Recording

__all__ = ["CHUNK", "dc_lines", "recording_means", "remove_dc"]

#: samples a channel read at a time while the means are measured
CHUNK = 1 << 18


def _stats(rec: Recording, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(sum, finite count, min, max) per channel of samples ``a`` to ``b``, NaN left out."""
    C = rec.n_channels
    total, count = np.zeros(C), np.zeros(C, dtype=np.int64)
    lo, hi = np.full(C, np.inf), np.full(C, -np.inf)
    for s in range(a, b, CHUNK):
        x = rec.samples.read(s, min(b, s + CHUNK))
        ok = np.isfinite(x)
        total += np.where(ok, x, 0.0).sum(axis=1)
        count += ok.sum(axis=1)
        if ok.any():
            lo = np.fmin(lo, np.fmin.reduce(x, axis=1))
            hi = np.fmax(hi, np.fmax.reduce(x, axis=1))
    return total, count, lo, hi


def remove_dc(rec: Recording) -> None:
    """Set ``rec.dc`` (snapshots, channels): the mean to subtract from each snapshot's samples
    (each snapshot's own; one snapshot: the whole recording's), and ``rec.dc_peak``: each
    channel's largest |x - mean| (what :attr:`Recording.peak` then gives)."""
    S, C = len(rec.snapshots), rec.n_channels
    means = np.zeros((S, C))
    peak = np.zeros(C)
    counts = np.zeros((S, C), dtype=np.int64)
    for k, snap in enumerate(rec.snapshots):
        total, count, lo, hi = _stats(rec, snap.start, snap.start + snap.length)
        m = np.divide(total, count, out=np.zeros(C), where=count > 0)
        means[k], counts[k] = m, count
        seen = count > 0
        peak[seen] = np.maximum(peak[seen], np.maximum(hi - m, m - lo)[seen])
    rec.dc, rec.dc_peak, rec.dc_counts = means, peak, counts


def dc_lines(rec: Recording) -> list[str]:
    """One line a channel on the mean taken out (:func:`remove_dc`), for the import's summary."""
    if rec.dc is None:
        return []
    why = "(the board's offset correction; --keep-dc keeps it)"
    lines = []
    for c, (name, unit) in enumerate(zip(rec.names, rec.units)):
        m = rec.dc[:, c]
        if m.size == 1:
            lines.append(f"  {name}: mean {m[0]:.4g} {unit} removed {why}")
            continue
        lines.append(f"  {name}: each snapshot's mean removed, {m.min():.4g} to {m.max():.4g} {unit} "
                     f"(over the recording {recording_means(rec)[c]:.4g} {unit}) {why}")
    return lines


def recording_means(rec: Recording) -> list[float]:
    """Each channel's mean over the whole recording (the snapshots' means weighted by the
    samples they hold); [] when :func:`remove_dc` has not run."""
    if rec.dc is None or rec.dc_counts is None:
        return []
    w = rec.dc_counts.sum(axis=0)
    total = (rec.dc * rec.dc_counts).sum(axis=0)
    return [float(v) for v in np.divide(total, w, out=np.zeros(rec.n_channels), where=w > 0)]
