"""The indicator settings an imported capture's sidecar gives a replay (and ``calibrate``, and
the site file it writes) when the configuration does not: the record length that keeps each
record within one snapshot, and the speed the import read from the files.

Records within snapshots. The import lays the snapshots end to end on the board clock, each
a whole number of blocks (:mod:`.blocks`), and the indicator chain cuts a record every
``indicators.interval_s`` from the stream's first sample (:mod:`cmsensord.monitor.indicators`).
Unless the record length divides the snapshots', records straddle them: the IMS rig's 1-s
snapshots (20,295 samples in 205-sample blocks) against 1-s records (20,480) put the end of
one snapshot and the start of the next in every record, with a step at the join in its
spectrum and its peak; FEMTO's 0.1-s snapshots put ten snapshots, 100 s apart in the
recording, in each 1-s record. With ``indicators.interval_s`` at its default, a capture of
snapshots gets the snapshots' common length instead (the greatest common divisor of every
snapshot's length but the last's, which ends the stream): one record a snapshot when they are
alike, or the largest whole part of one within ``MAX_INTERVAL_SAMPLES`` when it is longer. A
common length under ``MIN_RECORD_S`` (snapshots of unrelated lengths) is no record: the
setting stays and a line says the records straddle. An ``interval_s`` the configuration sets
is kept, with a line when its records straddle the snapshots. A restart of the records at each
snapshot's start would leave a partial record wherever the interval does not fit, without the
spectral indicators; a length the snapshots share keeps every record whole.

The speed. An import that read a constant speed from the files (an NPZ's ``rpm``, CWRU's
``X097RPM``) without ``--rpm`` sends no TACHO frames: the speed is in the sidecar only. A
configuration without ``indicators.rpm`` (and a capture without a tacho) takes it as
``indicators.rpm``: the bearing lines, order bands and the velocity band follow it, and the
records say ``speed_source: config`` (a speed given, not measured). Not when the files gave
different speeds (the import's note says which it kept): then a line says it is not used.

Captures. A capture (``capture.pre_s`` + ``post_s``) longer than the snapshots holds several
of them end to end, each of another time of the recording: a line says so.
"""

from __future__ import annotations

import dataclasses
import math

from cmsensord.config import Config
from cmsensord.config.indicators import IndicatorsConfig
from cmsensord.monitor.indicators import MAX_INTERVAL_SAMPLES

__all__ = ["MIN_RECORD_S", "SPEEDS_DIFFER", "capture_settings"]

#: the shortest record the snapshots' common length may give (FEMTO's snapshots: 0.1 s)
MIN_RECORD_S = 0.1
#: how the import's note on files that give different speeds begins
SPEEDS_DIFFER = "the files give different speeds"
_DEFAULT_INTERVAL_S = IndicatorsConfig().interval_s


def _common_samples(meta: dict) -> tuple[int, int] | None:
    """(the snapshots' common length in samples, fs) of an import of several snapshots, else None."""
    snaps = meta.get("snapshots") if meta.get("format") == "cmsensord import" else None
    fs = meta.get("fs")
    if not snaps or len(snaps) < 2 or not fs:
        return None
    common = math.gcd(*(int(s.get("length") or 0) for s in snaps[:-1]))
    return (common, int(fs)) if common else None


def _interval(cfg: Config, meta: dict) -> tuple[float | None, str | None]:
    """(the interval_s to set or None, a line on it or None)."""
    shared = _common_samples(meta)
    if shared is None:
        return None, None
    common, fs = shared
    n = max(2, min(MAX_INTERVAL_SAMPLES, round(cfg.indicators.interval_s * fs)))
    if common % n == 0:
        return None, None
    given = cfg.indicators.interval_s != _DEFAULT_INTERVAL_S
    fit = common if common <= MAX_INTERVAL_SAMPLES else \
        max(d for d in range(1, min(n, MAX_INTERVAL_SAMPLES) + 1) if common % d == 0)
    if given or fit < MIN_RECORD_S * fs:
        why = ("indicators.interval_s is set" if given else
               f"the snapshots share no length of {MIN_RECORD_S:g} s or more")
        return None, (f"indicators: records of {n} samples ({n / fs:g} s) straddle the capture's snapshots "
                      f"(their lengths are multiples of {common} samples only; {why}): a record may hold the end of "
                      f"one and the start of the next")
    what = "one record a snapshot" if fit == common else f"{common // fit} records a snapshot"
    return fit / fs, (f"indicators.interval_s {fit / fs:.6g} ({fit} samples, {what}) from the capture's "
                      f"snapshots of {common} samples: a record of the default {n / fs:g} s would straddle them")


def _speed(cfg: Config, meta: dict) -> tuple[float | None, str | None]:
    """(the rpm to set or None, a line on it or None)."""
    rpm = meta.get("rpm")
    if cfg.indicators.rpm is not None or not rpm or meta.get("tacho") or meta.get("format") != "cmsensord import":
        return None, None
    if meta.get("rpm_differs") or any(str(n).startswith(SPEEDS_DIFFER) for n in meta.get("notes") or []):
        return None, (f"indicators: the capture's {float(rpm):g} rpm is not used: its files gave different "
                      "speeds; give indicators.rpm in --config")
    return float(rpm), (f"indicators.rpm {float(rpm):g} from the capture (the speed its import read from "
                        f"{meta.get('rpm_source') or 'the file'}): bearing lines, order bands and the velocity band "
                        "at that speed")


def _captures(cfg: Config, meta: dict) -> str | None:
    """A line when the captures configured (``capture.triggers``, ``every_s``) are longer than
    the capture's snapshots: their waveforms and spectra then join snapshots of other times."""
    shared, cc = _common_samples(meta), cfg.capture
    if shared is None or not (cc.triggers or cc.every_s):
        return None
    common, fs = shared
    span = cc.pre_s + cc.post_s
    if span * fs <= common:
        return None
    return (f"capture: a capture of {span:g} s (capture.pre_s + post_s) holds about {math.ceil(span * fs / common)} "
            f"of the recording's snapshots of {common / fs:g} s, laid end to end: its waveform and spectra join "
            f"records of other times; pre_s + post_s <= {common / fs:g} s keeps it within one or two")


def capture_settings(cfg: Config, meta: dict) -> tuple[Config, dict[str, float], list[str]]:
    """``cfg`` with the indicator settings the sidecar ``meta`` gives (see module docstring;
    ``meta`` {}: not an import, ``cfg`` as it is), those settings by name, and one line on each
    (set, or why not)."""
    interval, said_interval = _interval(cfg, meta)
    rpm, said_speed = _speed(cfg, meta)
    changes = {k: v for k, v in (("interval_s", interval), ("rpm", rpm)) if v is not None}
    ic = cfg.indicators
    if changes:
        ic = dataclasses.replace(ic, interval_s=changes.get("interval_s", ic.interval_s),
                                 rpm=changes.get("rpm", ic.rpm))
        cfg = dataclasses.replace(cfg, indicators=ic)
    return cfg, changes, [line for line in (said_interval, said_speed, _captures(cfg, meta)) if line]
