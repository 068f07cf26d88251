"""Which arrays of an ``.npz`` archive, or variables of a ``.mat`` file, are the data
(``--array`` / ``--variable``), and the scalars that say the file's rate and speed.

* ``chosen`` is a comma-separated list; each item names one array, or is a pattern
  (``*_DE_time``) that matches exactly one: the CWRU bearing data centre names a file's
  variables after its record (``X097_DE_time``, ``X097_FE_time``), so one pattern picks the
  same sensor in every file (where a file holds another record's too, the one whose number
  its own name carries).  Their columns are laid side by side (the same number of
  samples each); a pattern's columns are named by its text without the wildcards
  (``DE_time``), so that every file has the same layout. The one exception is the speed
  column (``slow``, ``--speed-column``), which loggers often sample slower (Paderborn: the
  speed at 4 kHz beside the vibration at 64 kHz): with fewer samples it is taken to span the
  same time and is interpolated linearly to the others' samples, and the import says so.
* Without ``chosen``, the one numeric array with two dimensions, else the one with more than
  one element (:func:`pick_data`).
* A MATLAB struct's fields are variables named ``struct.field`` (:func:`flatten`; the MFPT
  bearing files hold ``bearing.gs``, the signal, and ``bearing.sr``, its rate), an array of
  structs' ``struct.NAME.field`` (Paderborn: ``'*vibration_1.Data'``).
* Scalars (:func:`scalar_named`) are found by the last part of their name; the speed also
  by a name that ends in ``rpm`` (CWRU: ``X097RPM``), or as a struct's ``rate`` in Hz beside
  its sampling rate (MFPT: ``bearing.rate``, :func:`shaft_rate`).
"""

from __future__ import annotations

import fnmatch
import re
from collections import Counter
from pathlib import Path

import numpy as np

from .errors import ImportFailure
from .table import RPM_KEYS, as_snapshot_array

__all__ = ["flatten", "pick_data", "scalar_named", "rpm_named", "shaft_rate", "selected", "stretched"]

#: how deep :func:`flatten` looks into structs within structs
MAX_DEPTH = 3


def flatten(arrays: dict, depth: int = MAX_DEPTH) -> dict:
    """``arrays`` with each MATLAB struct (a record array, as ``scipy.io.loadmat`` returns it)
    replaced by its fields: ``struct.field`` for a 1 x 1 struct; for an array of structs,
    ``struct.LABEL.field``, LABEL the element's ``Name`` field where it holds one word (the
    Paderborn bearing files: ``...Y.vibration_1.Data``), followed by ``_i`` where other
    elements hold the same word, so that no element's fields hide another's (``X.Time_0``,
    ``X.Time_1``); else ``[i]``; ``i`` the element's index from 0."""
    out: dict = {}
    for name, v in arrays.items():
        names = getattr(getattr(v, "dtype", None), "names", None)
        if not names or depth <= 0:
            out[name] = v
            continue
        recs = v.reshape(-1)
        labels = [_label(rec, names, i) for i, rec in enumerate(recs)]
        times = Counter(labels)
        labels = [lab if times[lab] == 1 or lab.startswith("[") else f"{lab}_{i}"
                  for i, lab in enumerate(labels)]
        for lab, rec in zip(labels, recs):
            at = name if recs.size == 1 else f"{name}.{lab}"
            out.update(flatten({f"{at}.{f}": rec[f] for f in names}, depth - 1))
    return out


def _label(rec, names: tuple[str, ...], i: int) -> str:
    """An element of an array of structs: its ``Name`` (any case) when that is one word, else ``[i]``."""
    field = next((f for f in names if f.lower() == "name"), None)
    value = np.asarray(rec[field]).ravel() if field else np.empty(0)
    word = str(value[0]) if value.size == 1 and value.dtype.kind == "U" else ""
    return word if re.fullmatch(r"\w+", word) else f"[{i}]"


def _numeric(v) -> bool:
    return isinstance(v, np.ndarray) and v.dtype.kind in "iufb"


def scalar_named(arrays: dict, keys: tuple[str, ...]) -> float | None:
    """The value of the first numeric scalar whose name's last part (after a ``.``), in lower
    case, is one of ``keys``."""
    return _scalar(arrays, lambda name: name in keys)


def rpm_named(arrays: dict, path: str = "") -> float | None:
    """The shaft speed: a scalar named like :data:`~.table.RPM_KEYS`, else one whose name ends
    in ``rpm`` (of several, the one whose number the file's name ``path`` carries: CWRU's
    ``99.mat`` holds record 98's ``X098RPM`` too)."""
    got = scalar_named(arrays, RPM_KEYS)
    if got is not None:
        return got
    named = [k for k in arrays if k.rsplit(".", 1)[-1].lower().endswith("rpm")]
    own = _of_the_file(path, named) if len(named) > 1 else []
    return _scalar({k: arrays[k] for k in own or named}, lambda name: True)


def shaft_rate(arrays: dict, fs_keys: tuple[str, ...]) -> tuple[str, float, str] | None:
    """(its name, its value in Hz, the sampling rate's name) of a scalar named ``rate`` in a
    struct that also holds the sampling rate, a positive number below half that rate: the
    shaft's speed in Hz, as the MFPT bearing files hold it (``bearing.rate`` 25 beside
    ``bearing.sr`` 97656); else None."""
    for name, v in arrays.items():
        head, _, last = name.rpartition(".")
        if last.lower() != "rate" or not head:
            continue
        sr = next((k for k in arrays if k.rpartition(".")[0] == head and k.rpartition(".")[2].lower() in fs_keys),
                  None)
        hz, fs = _scalar({name: v}, lambda _: True), _scalar({sr: arrays[sr]}, lambda _: True) if sr else None
        if hz is not None and fs is not None and 0 < hz < fs / 2:
            return name, hz, str(sr)
    return None


def _scalar(arrays: dict, match) -> float | None:
    for name, v in arrays.items():
        if match(name.rsplit(".", 1)[-1].lower()):
            v = np.asarray(v)
            if v.size == 1 and v.dtype.kind in "iuf":
                return float(v.reshape(()))
    return None


def _listing(arrays: dict, shapes: bool = True) -> str:
    """The numeric arrays' names (and shapes); the others (a struct's text fields) counted."""
    numeric = [f"{k} {tuple(np.shape(v))}" if shapes else k for k, v in arrays.items() if _numeric(v)]
    other = len(arrays) - len(numeric)
    return ", ".join(numeric) + (f"{'; ' if numeric else ''}{other} of text or other types not listed" if other
                                 else "" if numeric else "none")


def pick_data(path: str, arrays: dict, option: str, what: str) -> str:
    """The name of the only candidate data array (see module docstring)."""
    numeric = {k: v for k, v in arrays.items() if _numeric(v)}
    multi = [k for k, v in numeric.items() if v.ndim >= 2 and min(v.shape) >= 1 and v.size > 1]
    if len(multi) != 1:
        multi = [k for k, v in numeric.items() if v.size > 1]
    if len(multi) == 1:
        return multi[0]
    raise ImportFailure(f"{path}: {'no numeric ' + what if not multi else 'several ' + what + 's'} "
                        f"to import ({what}s: {_listing(arrays)}); choose one with {option} "
                        f"(several: {option} A,B)")


def _one(path: str, arrays: dict, item: str, option: str, what: str) -> tuple[str, str]:
    """(the array's name, its columns' name) for one item of ``chosen``."""
    if item in arrays:
        return item, item
    if not any(c in item for c in "*?["):
        raise ImportFailure(f"{path}: no {what} {item!r} ({what}s: {_listing(arrays, False)}); "
                            f"use {option}")
    hits = [k for k in arrays if fnmatch.fnmatchcase(k, item)]
    if len(hits) > 1:
        hits = _of_the_file(path, hits) or hits
    if len(hits) != 1:
        found = f"{len(hits)} {what}s match it ({', '.join(hits)})" if hits else f"no {what} matches it"
        raise ImportFailure(f"{path}: {option} {item}: {found} ({what}s: {_listing(arrays, False)}); "
                            "give a pattern that matches one")
    return hits[0], re.sub(r"[*?]|\[[^]]*\]", "", item).strip("_.") or "data"


def _of_the_file(path: str, hits: list[str]) -> list[str]:
    """The one of ``hits`` whose name carries the number the file's name ends in (CWRU's
    ``99.mat`` also holds record 98's ``X098_DE_time`` beside its own ``X099_DE_time``), or none."""
    own = re.findall(r"\d+", Path(path).stem)
    mine = [k for k in hits if own and int(own[-1]) in {int(d) for d in re.findall(r"\d+", k)}]
    return mine if len(mine) == 1 else []


def selected(path: str, arrays: dict, chosen: tuple[str, ...] | None, option: str, what: str,
             slow: str | None = None) -> tuple[np.ndarray, list[str], str | None]:
    """The data, (snapshots, samples, columns), its columns' names, and a note when the speed
    column ``slow`` (a name or an index) was sampled slower (see module docstring)."""
    picks = [_one(path, arrays, item, option, what) for item in chosen] if chosen else \
        [(n := pick_data(path, arrays, option, what), n)]
    parts: list[np.ndarray] = []
    columns: list[str] = []
    for name, label in picks:
        v = arrays[name]
        if not _numeric(v):
            kind = "a struct" if getattr(getattr(v, "dtype", None), "names", None) else \
                f"of type {getattr(v, 'dtype', type(v).__name__)}"
            raise ImportFailure(f"{path}: {what} {name!r} is {kind}, not a numeric array; "
                                f"choose a numeric one with {option}")
        parts.append(as_snapshot_array(path, f"{what} {name!r}", v))
        columns += [label] if parts[-1].shape[2] == 1 else [f"{label}_{i}" for i in range(parts[-1].shape[2])]
    is_slow = [slow is not None and a.shape[2] == 1 and slow in (label, str(columns.index(label)))
               for a, (_, label) in zip(parts, picks)]
    ref = next((k for k, s in enumerate(is_slow) if not s), 0)
    note = None
    for k, a in enumerate(parts):
        if a.shape[:2] == parts[ref].shape[:2]:
            continue
        if is_slow[k] and a.shape[0] == parts[ref].shape[0] and 2 <= a.shape[1] < parts[ref].shape[1]:
            parts[k], note = stretched(a, parts[ref].shape[1]), (
                f"{picks[k][1]}: {a.shape[1]} samples beside {parts[ref].shape[1]} of {picks[ref][1]}: "
                f"taken as the same time sampled {parts[ref].shape[1] / a.shape[1]:.4g} x slower, "
                "interpolated linearly")
            continue
        hint = "; a speed sampled slower: name it with --speed-column" if 2 * a.shape[1] <= parts[ref].shape[1] \
            and a.shape[2] == 1 and not is_slow[k] else ""
        raise ImportFailure(f"{path}: {what} {picks[k][0]!r} holds {a.shape[1]} samples x {a.shape[0]} "
                            f"snapshot(s), {picks[ref][0]!r} {parts[ref].shape[1]} x {parts[ref].shape[0]}; "
                            f"{option} takes {what}s of the same length{hint}")
    return (parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)), columns, note


def stretched(a: np.ndarray, n: int) -> np.ndarray:
    """(snapshots, m, 1) sampled over the same time as ``n`` samples, interpolated to them."""
    m = a.shape[1]
    at = np.arange(n) * (m / n)
    return np.stack([np.interp(at, np.arange(m), row[:, 0]) for row in a])[:, :, None]
