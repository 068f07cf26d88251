"""Which of a bearing's envelope-spectrum lines the spectrum's bins can resolve.

A line at f0 is read as the largest bin within f0 (1 +/- slip), the window widened to at
least +/- one bin df (:func:`~.envelope.line_peak`); df is 1 / the record's length (the
envelope spectrum of a record of T s has bins of 1 / T Hz, whatever the decimation).  A
line is *unresolved*, and given no number, when

* **the bin is too coarse for it**: df > max(slip, ``WIDEST``) x f0, i.e. the window widened
  to a bin reaches beyond the slip and beyond +/- 10 % of the line: the line stands fewer
  than 10 bins up (FTF at 12.95 Hz in 10-Hz bins: +/- 77 %).  ``WIDEST`` = 10 %: a line is
  where its bearing's 1-2 % slip and the error of the speed put it, and a speed configured
  rather than measured (``indicators.rpm``, an import's) can be off a loaded induction
  motor's by its slip, up to ~5 %: a window of up to +/- 10 % reads where the line can be, a
  wider one mostly where it cannot.  It is also the README's rule of thumb for a spectrum
  component (at least 10 bins up).  A line 10-20 bins up may be read from either of two
  bins (FEMTO's BPFO at 168.3 Hz from 160 or 170): where it stands out its own bin is the
  larger, where it does not both are the floor;
* **its window overlaps another line's of the same bearing**: windows [f0 - h, f0 + h],
  h = max(slip x f0, df), that overlap can take the same bin for both lines (FTF and
  2 x FTF, 2 x BSF and BPFI), so neither number says which line it is.  This holds at any
  bin width when the slip windows themselves overlap: no record length separates those.

:func:`unresolved` gives the lines so judged; :func:`record_s_to_resolve` the shortest record
that resolves a line; :func:`unresolved_line` the one line that tells an operator.

A line's window can also hold a harmonic of another defect frequency of the same bearing that is
not read as a line itself: the third (the second of each is its ``_2x`` line, whose window
overlapping is the case above).  A 6206's 2 x BPFI (10.84 x f_r) lies 0.9 % above 3 x BPFO
(10.74 x f_r): an outer-race defect raises ``bpfi_2x`` as much as ``bpfo_2x``.  The lines are all
in proportion to the shaft speed, so this holds at every speed: :func:`harmonic_overlaps` finds
them, :func:`harmonic_line` tells an operator once.
"""

from __future__ import annotations

import math

from .bearings import DEFECTS, DefectFrequencies

__all__ = ["WIDEST", "line_freqs", "unresolved", "record_s_to_resolve", "unresolved_line", "harmonic_overlaps",
           "harmonic_line"]

#: the widest a window widened to a bin may be, as a fraction of the line's frequency
WIDEST = 0.10
#: harmonics of each defect frequency read from the envelope spectrum
HARMONICS = (1, 2)
#: the harmonic of a defect frequency looked for in other lines' windows (the next one not read)
UNREAD_HARMONIC = 3


def line_freqs(freqs: DefectFrequencies) -> dict[str, float]:
    """The lines read for defect frequencies ``freqs`` [Hz]: ``ftf``, ``ftf_2x``, ``bpfo``, ... -> Hz."""
    return {name if h == 1 else f"{name}_{h}x": h * f0 for name, f0 in zip(DEFECTS, freqs) for h in HARMONICS}


def _half(f0: float, slip: float, df: float) -> float:
    return max(slip * f0, df)


def unresolved(lines: dict[str, float], slip: float, df: float) -> tuple[str, ...]:
    """The names of the lines (name -> Hz) that bins of ``df`` Hz do not resolve at ``slip``
    (a fraction), in the order of ``lines`` (see module docstring)."""
    bad = set()
    items = sorted(lines.items(), key=lambda kv: kv[1])
    for i, (name, f0) in enumerate(items):
        h = _half(f0, slip, df)
        if df > max(slip, WIDEST) * f0:
            bad.add(name)
        for other, f1 in items[i + 1:]:
            if f1 - _half(f1, slip, df) < f0 + h:
                bad.update((name, other))
    return tuple(k for k in lines if k in bad)


def record_s_to_resolve(name: str, lines: dict[str, float], slip: float) -> float | None:
    """The shortest record [s] (bins of 1 / it) that resolves line ``name`` of ``lines``, None
    when none does (its slip window overlaps another line's)."""
    f0 = lines[name]
    df = max(slip, WIDEST) * f0                      # the coarsest bin not too coarse for it
    for other, f1 in lines.items():
        if other == name:
            continue
        fa, fb = sorted((f0, f1))
        gap = fb - fa
        if slip * (fa + fb) > gap:
            return None
        # the windows max(slip fa, d) + max(slip fb, d) meet the gap at d = gap / 2 or gap - slip fb
        df = min(df, gap / 2 if gap >= 2 * slip * fb else gap - slip * fb)
    return 1.0 / df


def unresolved_line(bearing: str, channel: str, names: tuple[str, ...], lines: dict[str, float], slip: float,
                    df: float, rules: tuple[str, ...] = (), longest_s: float | None = None) -> str:
    """The line that tells an operator that ``names`` of ``bearing`` on ``channel`` are unresolved
    at bins of ``df`` Hz: unavailable, the ``rules`` on them do not fire, and what resolves
    them (the record length; ``longest_s``: the longest record this set-up can have)."""
    need = {k: record_s_to_resolve(k, lines, slip) for k in names}
    never = [k for k, s in need.items() if s is None]
    longer = [k for k, s in need.items() if s is not None]
    what = f"rule(s) {', '.join(rules)} on them do not fire" if rules else "an alarm rule on them would never fire"
    out = (f"bearing {bearing} on {channel}: line(s) {', '.join(f'{k} {lines[k]:.4g} Hz' for k in names)} not "
           f"resolved by the envelope spectrum's {df:.3g}-Hz bins (records of {1 / df:.3g} s): each one's window, "
           f"±{slip * 100:g} % widened to ±1 bin, is wider than ±{WIDEST * 100:g} % of it or overlaps another "
           f"line's; listed unavailable in /cm/{channel}/indicators, no number; {what}")
    if longer:
        s = max(need[k] or 0.0 for k in longer)
        s = math.ceil(s * 100 - 1e-6) / 100
        fits = "" if longest_s is None or s <= longest_s else \
            f", longer than a record can be at this rate ({longest_s:.3g} s)"
        out += (f"; records of at least {s:g} s resolve {', '.join(longer)} (indicators.interval_s; an imported "
                f"capture's records are its snapshots: import longer ones){fits}")
    if never:
        out += (f"; {', '.join(never)} lie within the slip (±{slip * 100:g} %) of another line of {bearing}: no "
                "record length resolves them")
    return out


def harmonic_overlaps(freqs: DefectFrequencies, slip: float,
                      skip: tuple[str, ...] = ()) -> list[tuple[str, str, float]]:
    """(line, defect, its harmonic's Hz) for each line of ``freqs`` (not in ``skip``) whose
    window of +/- ``slip`` holds :data:`UNREAD_HARMONIC` x another defect frequency of them."""
    out = []
    for name, f0 in line_freqs(freqs).items():
        if name in skip:
            continue
        for defect, f1 in zip(DEFECTS, freqs):
            h = UNREAD_HARMONIC * f1
            if not name.startswith(defect) and abs(h - f0) <= slip * f0:
                out.append((name, defect, h))
    return out


def harmonic_line(bearing: str, channel: str, overlaps: list[tuple[str, str, float]],
                  lines: dict[str, float], slip: float, rules: tuple[str, ...] = ()) -> str:
    """The line that tells an operator that the windows of bearing ``bearing``'s lines on
    ``channel`` hold the harmonics ``overlaps`` (:func:`harmonic_overlaps`) of other lines,
    with the ``rules`` on those lines."""
    said = []
    for name, defect, h in overlaps:
        base = name.removesuffix("_2x")
        judge = f" (judge {base} by {bearing}.{base}_ratio)" if base != name else ""
        said.append(f"{name}'s window ({lines[name]:.4g} Hz ±{slip * 100:g} %) holds {UNREAD_HARMONIC} x {defect} "
                    f"({h:.4g} Hz): a defect at {defect} raises {bearing}.{name} too{judge}")
    watch = f"; rule(s) {', '.join(rules)} on it fire on that defect as well" if rules else ""
    return f"bearing {bearing} on {channel}: {'; '.join(said)}{watch}"
