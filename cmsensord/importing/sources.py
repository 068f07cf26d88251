"""SRC arguments to files in time order, and files to one :class:`Recording`.

Files: each SRC is a file, a directory (its files of the most common supported
extension, or its text tables of numbers under other names: the IMS rig's files are
named by date and time) or a glob pattern (also ``--glob``). They are taken in natural
name order (``acc_2`` before ``acc_10``, ``20.0704.csv`` before ``20.48.csv``) unless
``order`` is ``mtime`` (modification time) or ``given`` (as listed). Every file is one contiguous snapshot, or
several (a 3-D array, or ``snapshot_len``); the snapshots are laid end to end. Two files or
more of many snapshots of their own are whole recordings, refused unless ``join_recordings``.
Snapshot times come from ``snapshot_interval``, else the files themselves, else the
files' names (:mod:`.name_times`).

Channels: ``channels`` picks columns by index (from 0) or name, the same for
every file; the default is every column but the tacho column, at most 8 (the
board's limit). Values become m/s² by :func:`.units.to_ms2_factor`.
"""

from __future__ import annotations

import fnmatch
import glob as globmod
import os
import re
import stat
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from cmsensord.errors import bad_link, file_kind
from cmsensord.sinks.mcap_records import is_capture

from .arrays import read_npy, read_npz
from .channel_names import channel_names, checked_names
from .columns import Columns
from .errors import ImportFailure
from .known_sets import rate_hint
from .matlab import read_mat
from .options import ImportOptions
from .recording import Recording, Snapshot
from .samples import SampleStore
from .snapshot_times import retimed
from .table import Table
from .tabular import LongText, is_text_table, read_tabular
from .tacho import MAX_PPR, board_ppr, every_kth, pulse_edges, speed_edges
from .tdms import read_tdms
from .units import per_channel, resolve_units, to_ms2_factor, unit_in_name, unit_in_suffix, unit_of
from .wav import read_wav

__all__ = ["EXTENSIONS", "collect_files", "read_table", "build_recording", "MAX_CHANNELS"]

EXTENSIONS = (".wav", ".csv", ".tsv", ".txt", ".lvm", ".npy", ".npz", ".mat", ".tdms")
MAX_CHANNELS = 8
#: the largest sampling rate STATUS carries (its fs field: 32 bits)
MAX_FS = 0xFFFF_FFFF
#: samples a channel converted at a time (2 MB of float64 each)
READ_SAMPLES = 1 << 18


#: a file's stem that is one decimal number (MAFAULDA names its files by speed: ``20.48.csv``)
_DECIMAL_STEM = re.compile(r"\d+\.\d+")


def _natural_key(path: str) -> list:
    """Natural name order: runs of digits by their value (``acc_2`` before ``acc_10``); a file
    whose whole stem is a decimal number (``9.8304.csv``, ``20.0704.csv``, ``20.48.csv``) by that
    number. Names of several dots (``2004.02.12.10.32.39``) or more than a number
    (``run1.10``) keep the order of their runs of digits."""
    p = Path(path)
    if _DECIMAL_STEM.fullmatch(p.stem):
        head = path[:len(path) - len(p.name)]
        return [*_natural_key(head), float(p.stem), p.suffix.lower()]
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path)]


def _kind(p: Path) -> str | None:
    """What a file in a directory is: its known extension, ``text`` (a text table of numbers
    under another name, :func:`~.tabular.is_text_table`) or None (not a recording)."""
    ext = p.suffix.lower()
    if ext in EXTENSIONS:
        return ext
    return "text" if not p.name.startswith(".") and is_text_table(str(p)) else None


def _pattern(p: Path) -> str:
    """A file's name with each run of digits as ``#``: the snapshots of one series share it."""
    return re.sub(r"\d+", "#", p.name)


def _dir_files(d: Path, notes: list[str]) -> list[str]:
    """The directory's recording files of the most common kind (:func:`_kind`); the others
    (another extension, not a recording: a ``README.txt`` beside ``.csv`` files), but hidden
    ones, are left out with a note naming them. When several series of the files taken are
    there (two files or more named alike, :func:`_pattern`: FEMTO's ``acc_00001.csv`` beside
    its ``temp_00001.csv``), only the largest, and a note names what was left out. Empty files
    (a logger's, created when it stopped) are left out with a note."""
    sizes = {p: p.stat().st_size for p in d.iterdir() if p.is_file()}
    empty = sorted((p for p, size in sizes.items() if not size), key=lambda p: _natural_key(p.name))
    if empty:
        notes.append(f"{d}: left out {len(empty)} empty file(s) ({', '.join(p.name for p in empty[:3])}"
                     f"{', ...' if len(empty) > 3 else ''})")
    kinds = {p: _kind(p) for p, size in sizes.items() if size}
    files = [p for p, k in kinds.items() if k is not None]
    if not files:
        raise ImportFailure(f"{d}: no recording files ({', '.join(EXTENSIONS)}, or text tables of numbers) "
                            "in this directory; give the files or a --glob pattern")
    kind = min(Counter(kinds[p] for p in files).items(), key=lambda kv: (-kv[1], kv[0]))[0]
    files = [p for p in files if kinds[p] == kind]
    other = sorted((p.name for p, k in kinds.items() if k != kind and not p.name.startswith(".")), key=_natural_key)
    if other:
        notes.append(f"{d}: took the {len(files)} {'text table' if kind == 'text' else kind} file(s); left out "
                     f"{len(other)} of another type ({', '.join(other[:3])}{', ...' if len(other) > 3 else ''})")
    series = Counter(_pattern(p) for p in files)
    if sum(n > 1 for n in series.values()) < 2:
        return [str(p) for p in files]
    best = min(series, key=lambda name: (-series[name], name))
    left = sorted(name for name in series if name != best)
    notes.append(f"{d}: took the {series[best]} file(s) named like {best}; left out {len(files) - series[best]} "
                 f"other(s) ({', '.join(left[:3])}{', ...' if len(left) > 3 else ''}): name them to import them")
    return [str(p) for p in files if _pattern(p) == best]


def collect_files(srcs: list[str], globs: list[str], order: str, notes: list[str] | None = None) -> list[str]:
    """The files named by ``srcs`` and ``globs``, in ``order`` (``given``: the sources in turn, a
    directory's files and a pattern's matches each in natural name order); what a directory left
    out is appended to ``notes``."""
    files: list[str] = []
    named: list[str] = []                       # the files named one by one, as given
    for src in srcs:
        p = Path(src)
        if p.is_dir():
            files += sorted(_dir_files(p, [] if notes is None else notes), key=_natural_key)
        elif p.exists():
            files.append(src)
            named.append(src)
        elif globmod.has_magic(src):
            hit = [f for f in globmod.glob(src) if os.path.isfile(f)]
            if not hit:
                raise ImportFailure(f"{src}: no file matches this pattern; check the path")
            files += sorted(hit, key=_natural_key)
        else:
            raise ImportFailure(f"{src}: {bad_link(src, 'the recording') or 'no such file or directory'}")
    for pattern in globs:
        hit = [f for f in globmod.glob(pattern) if os.path.isfile(f)]
        if not hit:
            raise ImportFailure(f"--glob {pattern}: no file matches this pattern; check the path")
        files += sorted(hit, key=_natural_key)
    if not files:
        raise ImportFailure("no recording given; name files, a directory, or --glob PATTERN")
    if order == "name":
        files.sort(key=_natural_key)
        if notes is not None:
            notes += _reordered(named)
    elif order == "mtime":
        files.sort(key=lambda f: (os.path.getmtime(f), _natural_key(f)))
    return files


def _reordered(named: list[str]) -> list[str]:
    """A note when name order puts files named one by one out of the order they were given in,
    unless that order was a shell's (a pattern it expanded: sorted by character, case aside)."""
    ordered = sorted(named, key=_natural_key)
    if ordered == named or named == sorted(named, key=str.casefold):
        return []
    i = next(k for k, (a, b) in enumerate(zip(ordered, named)) if a != b)
    first, then = Path(ordered[i]).name, Path(named[i]).name
    if first == then:                           # the same name in two directories
        first, then = ordered[i], named[i]
    return [f"the files are taken in name order: {first} before {then}, not in the order given (--order given "
            "keeps it)"]


def read_table(path: str, opts: ImportOptions, progress: Callable[[float], None] | None = None) -> Table:
    """The file's table, by its extension (``progress(fraction)`` while a long text file is read);
    an unreadable file, or one that is not a regular file (a FIFO would wait for a writer, a
    device give bytes without end), is a one-line ImportFailure."""
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
            raise ImportFailure(f"{path}: not a regular file (a {file_kind(mode)}): import reads the files of a "
                                f"recording ({', '.join(EXTENSIONS)}, or text tables of numbers)")
        return _read_by_extension(path, opts, progress)
    except OSError as exc:
        raise ImportFailure(f"{path}: cannot read: {exc.strerror or exc}") from None


def _read_by_extension(path: str, opts: ImportOptions, progress: Callable[[float], None] | None) -> Table:
    ext = Path(path).suffix.lower()
    if ext == ".wav":
        return read_wav(path)
    if ext in (".csv", ".tsv", ".txt", ".lvm"):     # .lvm: LabVIEW's text measurement file
        return read_tabular(path, opts.separator, opts.header, _long_text(opts, progress))
    if ext == ".npy":
        return read_npy(path)
    if ext == ".npz":
        return read_npz(path, opts.array, opts.speed_column)
    if ext == ".mat":
        return read_mat(path, opts.variable, opts.speed_column, opts.rpm is not None)
    if ext == ".tdms":
        return read_tdms(path, opts.speed_column)
    if is_text_table(path):                 # a text table under another name (IMS: a date and time)
        return read_tabular(path, opts.separator, opts.header, _long_text(opts, progress))
    if is_capture(path):
        raise ImportFailure(f"{path}: a capture of the board's serial stream already (cmsensord's input): "
                            f"replay, calibrate and vkf read it as it is (`cmsensord replay {path} --out DIR`)")
    raise ImportFailure(f"{path}: unknown file type {ext or '(no extension)'}, and not a text table of "
                        f"numbers; supported: {', '.join(EXTENSIONS)}")


def _long_text(opts: ImportOptions, progress: Callable[[float], None] | None) -> LongText:
    """A long text table's numbers wait beside ``--out`` while it is read, past ``--memory-mb``."""
    return LongText(str(Path(opts.out).resolve().parent), opts.memory_mb, progress)


def _column(t: Table, token: str, option: str) -> int:
    n = len(t.columns)
    if re.fullmatch(r"\d+", token):
        i = int(token)
        if i >= n:
            raise ImportFailure(f"{t.path}: no {t.kind} {i} (the file has {n} {t.kind}s, "
                                f"numbered 0..{n - 1}); use {option}")
        return i
    if token in t.columns:
        return t.columns.index(token)
    raise ImportFailure(f"{t.path}: no {t.kind} {token!r} ({t.kind}s: {', '.join(t.columns)}); use {option}")


class _Layout:
    """Column choice, names and rate, fixed by the first file and checked on the others."""

    def __init__(self, t: Table, opts: ImportOptions):
        self.columns = list(t.columns)
        col, option = (opts.speed_column, "--speed-column") if opts.speed_column else \
            (opts.tacho_column, "--tacho-column")
        self.tacho = _column(t, col, option) if col else None
        if opts.channels:
            option = "--columns" if t.kind == "column" else "--channels"  # the same option
            self.idx = [_column(t, tok, option) for tok in opts.channels]
            twice = next((i for k, i in enumerate(self.idx) if i in self.idx[:k]), None)
            if twice is not None:
                raise ImportFailure(f"{option} {','.join(opts.channels)}: {t.kind} {t.columns[twice]!r} ({twice}) "
                                    "given twice; give each once")
        else:
            self.idx = [i for i in range(len(t.columns)) if i != self.tacho and i not in t.time_columns]
        if not self.idx:
            raise ImportFailure(f"{t.path}: no {t.kind} left to import besides the tacho; check --channels")
        if len(self.idx) > MAX_CHANNELS:
            raise ImportFailure(f"{t.path}: {len(self.idx)} {t.kind}s, the board carries at most "
                                f"{MAX_CHANNELS}; choose some with --channels (e.g. --channels 0,1)")
        self.notes = [n for n in (t.head_note, t.time_note, t.layout_note) if n]  # said once: preamble, time base, ...
        if opts.names:
            self.names = checked_names(list(opts.names))
        else:
            self.names, renamed = channel_names([t.columns[i] for i in self.idx])
            self.notes += renamed
        if len(self.names) != len(self.idx):
            raise ImportFailure(f"--names gives {len(self.names)} name(s) for {len(self.idx)} channel(s); "
                                "give one name per imported channel")
        fs = opts.fs if opts.fs is not None else t.fs
        if fs is None:
            why = f": {t.time_note}" if t.time_note else ""
            raise ImportFailure(f"{t.path}: the file does not say its sampling rate{why}; give --fs HZ"
                                f"{rate_hint(t.path, [t.columns[i] for i in self.idx])}")
        self.fs: float = fs
        self.file_fs = t.fs
        said = [(t.columns[i], unit_of(t.units[i]) if t.units else unit_in_name(t.columns[i])) for i in self.idx]
        suffix = {c: s for c, u in said if u is None and not t.units and (s := unit_in_suffix(c))}
        said = [(c, suffix[c][0] if c in suffix else u) for c, u in said]
        named = {c: s[1] for c, s in suffix.items()}
        what = {".npz": "array", ".npy": "array", ".mat": "variable"}.get(Path(t.path).suffix.lower(), t.kind)
        self.units, unit_notes = resolve_units(opts.unit, said, named, what)
        self.notes += unit_notes
        in_volts = [c for (c, _), u in zip(said, self.units) if u == "V"]
        if opts.unit is None and in_volts and opts.sensitivity is None:
            raise ImportFailure(f"{t.path}: the file gives its {t.kind}s in V ({', '.join(in_volts)}): "
                                "add the accelerometer's --sensitivity MV_PER_G (e.g. 100), or --unit for another")

    def factors(self, opts: ImportOptions) -> np.ndarray:
        """Each channel's physical unit per raw value, (C, 1): its unit's, ``--sensitivity`` and
        ``--scale-factor`` (one, or one per channel)."""
        n = len(self.units)
        sens, scale = per_channel(opts.sensitivity, n, "--sensitivity"), per_channel(opts.scale_factor, n,
                                                                                   "--scale-factor")
        if opts.sensitivity is not None and "V" not in self.units:
            to_ms2_factor(self.units[0], sens[0])           # its one-line error: V only
        return np.array([[to_ms2_factor(u, s if u == "V" else None, k)] for u, s, k in zip(self.units, sens, scale)])

    def check(self, t: Table, first_path: str) -> None:
        """A one-line ImportFailure when file ``t`` has other columns than the first file
        (``first_path``), or another rate, naming the difference."""
        first = Path(first_path).name
        if t.columns != self.columns:
            theirs, ours = _listed(t.columns), _listed(self.columns)
            what = (f"other {t.kind}s ({theirs}) than {first} ({ours})" if len(t.columns) == len(self.columns) else
                    f"{len(t.columns)} {t.kind}s ({theirs}) where {first} has {len(self.columns)} ({ours})")
            raise ImportFailure(f"{t.path}: {what}; every snapshot file must have the same layout: "
                                f"{_leave_out(t.path, first_path)}")
        if t.fs is not None and self.file_fs is not None and t.fs != self.file_fs:
            raise ImportFailure(f"{t.path}: sampled at {t.fs:g} Hz, {first} at {self.file_fs:g} Hz; "
                                "import them separately")


def _listed(names: list[str]) -> str:
    return ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")


def _leave_out(odd: str, first: str) -> str:
    """How to leave file ``odd`` out of an import of ``first``'s series: move it away, or a
    ``--glob`` pattern that matches ``first`` (its runs of digits as ``[0-9]*``, or any name
    ending in a digit) and not ``odd``, when one does."""
    name, parent = Path(first).name, Path(first).parent
    stem, suffix = Path(name).stem, Path(name).suffix
    tries = [re.sub(r"\d+", "[0-9]*", name)] + (["*[0-9]" + suffix] if stem[-1:].isdigit() else [])
    pattern = next((p for p in tries if p != name and fnmatch.fnmatchcase(name, p)
                    and not fnmatch.fnmatchcase(Path(odd).name, p)), None)
    if pattern is None:
        return "leave it out (move it away)"
    where = pattern if parent == Path(".") else str(parent / pattern)
    return f"leave it out (move it away, or import --glob '{where}' instead)"


def _missing_note(t: Table, names: list[str], missing: np.ndarray, first: tuple[int, int] | None) -> str | None:
    """One line on a file's missing values (``missing``: per channel; ``first``: the snapshot and
    sample of the first), or None when it has none."""
    if first is None:
        return None
    which = ", ".join(f"{name} ({int(n):,})" for name, n in zip(names, missing) if n)
    at = f"snapshot {first[0]}, sample {first[1]}" if t.data.shape[0] > 1 else f"sample {first[1]}"
    return (f"{t.name}: {int(missing.sum()):,} missing value(s) (NaN, inf or empty cells) in {which}, the first "
            f"at {at}: the blocks that hold them are left out of the capture, as frames the board lost (a "
            "replay counts their observations missing)")


def _split(t: Table, n: int | None) -> list[tuple[int, int, int]]:
    """(snapshot of the table, start, length) pieces of ``snapshot_len`` n (None: whole snapshots)."""
    s, length, _ = t.data.shape
    if not n:
        return [(k, 0, length) for k in range(s)]
    if s > 1:
        raise ImportFailure(f"{t.path}: already holds {s} snapshots; drop --snapshot-len")
    return [(0, a, min(n, length - a)) for a in range(0, length, n)]


def _channels(t: Table, layout: _Layout, factor: np.ndarray, notes: list[str]) -> Iterator[np.ndarray]:
    """The imported channels of one file in their physical units (``factor``: (C, 1)), (C, n)
    stretches of at most ``READ_SAMPLES`` in file order: one float64 copy of a stretch, not of
    the file. A missing or non-finite value is NaN there (its block is left out of the capture),
    and ``notes`` gets one line on them."""
    s_, n_, _ = t.data.shape
    missing = np.zeros(len(layout.idx), dtype=np.int64)
    first: tuple[int, int] | None = None
    for s in range(s_):
        for a in range(0, n_, READ_SAMPLES):
            x = np.empty((len(layout.idx), min(n_, a + READ_SAMPLES) - a))
            for c, i in enumerate(layout.idx):
                x[c] = t.data[s, a:a + x.shape[1], i]
            if t.zero:
                x -= t.zero
            with np.errstate(over="ignore"):    # a value the factor takes past float64: missing
                x *= t.gain * factor
            bad = ~np.isfinite(x)
            if bad.any():
                missing += bad.sum(axis=1)
                first = first or (s, a + int(np.flatnonzero(bad.any(axis=0))[0]))
                x[bad] = np.nan
            yield x
    note = _missing_note(t, [t.columns[i] for i in layout.idx], missing, first)
    if note:
        notes.append(note)


def _file_notes(t: Table, opts: ImportOptions) -> list[str]:
    """What the sidecar says about one file: what its reader noticed, snapshot times out of order,
    a short last snapshot."""
    notes = list(t.notes)
    if t.times is not None and (np.diff(t.times) <= 0).any():
        bad = np.flatnonzero(np.diff(t.times) <= 0)
        k = int(bad[0]) + 1
        notes.append(f"{t.name}: the snapshot times do not increase at {bad.size} place(s), first at "
                     f"snapshot {k} ({t.times[k - 1]:g} s -> {t.times[k]:g} s); the snapshots stay in "
                     "file order, the sidecar keeps the file's times")
    if opts.snapshot_len and t.data.shape[1] % opts.snapshot_len:
        notes.append(f"{t.name}: {t.data.shape[1]} samples are not a whole number of "
                     f"{opts.snapshot_len}-sample snapshots: the last one holds "
                     f"{t.data.shape[1] % opts.snapshot_len}")
    return notes


def _short_snapshots(snaps: list[Snapshot], opts: ImportOptions) -> list[str]:
    """A note on the snapshots much shorter than most (files cut short?), when there are a few
    (not ``--snapshot-len``'s last piece, which has its own)."""
    if len(snaps) < 3 or opts.snapshot_len:
        return []
    usual = int(np.median([s.length for s in snaps]))
    short = [s for s in snaps if s.length < 0.9 * usual]
    if not short:
        return []
    listed = ", ".join(f"{s.source} ({s.length:,})" for s in short[:3]) + (", ..." if len(short) > 3 else "")
    return [f"{len(short)} snapshot(s) hold far fewer samples than most ({usual:,}): {listed}; files cut short?"]


def _within(progress: Callable[[float], None] | None, fi: int) -> Callable[[float], None] | None:
    """``progress`` of the files done while file ``fi`` is read: ``fi`` + the fraction read."""
    if progress is None:
        return None
    return lambda fraction: progress(fi + fraction)


def build_recording(files: list[str], opts: ImportOptions, progress=None) -> Recording:
    """Read every file (``progress(files done)`` after each, and in fractions while a long text
    file is read) and lay the snapshots end to end in a
    :class:`~.samples.SampleStore` beside ``opts.out`` (the caller closes ``rec.samples``):
    past ``opts.memory_mb`` of samples, only one file's (and a tacho or speed column) are held
    in memory."""
    stores: list[SampleStore] = []
    try:
        return _build(files, opts, progress, stores)
    except BaseException:
        for store in stores:
            store.close()
        raise


def _build(files: list[str], opts: ImportOptions, progress, stores: list[SampleStore]) -> Recording:
    layout: _Layout | None = None
    tacho_pieces: list[np.ndarray] = []
    snaps: list[Snapshot] = []
    notes: list[str] = []
    rpms: list[tuple[float, str]] = []     # the speeds the files give, and which
    pos = 0
    origins: list[tuple[int, int]] = []     # per snapshot: (its file, its first sample in the file)
    own_times = clock = dated = False       # a file gave its snapshots' times (of day, or dated)
    whole: list[tuple[str, int]] = []       # the files of many snapshots of their own, and how many
    for fi, path in enumerate(files):
        t = read_table(path, opts, _within(progress, fi))
        _whole_recordings(whole, path, t.data.shape[0], files, opts)
        if layout is None:
            layout = _Layout(t, opts)
            factor = layout.factors(opts)
            stores.append(SampleStore(len(layout.idx), opts.out, opts.memory_mb))
        else:
            layout.check(t, files[0])
        if layout.tacho is not None:
            tacho_pieces.append(_tacho_column(t, layout.tacho, layout.fs, opts))
        many = t.data.shape[0] > 1 or opts.snapshot_len
        for k, (s, a, n) in enumerate(_split(t, opts.snapshot_len)):
            time = None if t.times is None or not np.isfinite(t.times[s]) else float(t.times[s])
            snaps.append(Snapshot(f"{t.name}[{k}]" if many else t.name, pos, n, time))
            origins.append((fi, a))
            pos += n
        own_times, clock, dated = own_times or t.times is not None, clock or t.clock, dated or t.dated
        notes += _file_notes(t, opts)
        try:
            for x in _channels(t, layout, factor, notes):
                stores[0].append(x)
        finally:
            if isinstance(t.data, Columns):     # read a stretch at a time from a file kept open
                t.data.close()
        if t.rpm and np.isfinite(t.rpm) and t.rpm > 0:
            rpms.append((t.rpm, t.name))
        del t
        if progress is not None:
            progress(fi + 1)
    assert layout is not None
    notes[:0] = layout.notes
    fs = layout.fs
    if not (np.isfinite(fs) and fs > 0):
        raise ImportFailure(f"{files[0]}: the sampling rate the file gives, {fs:g} Hz, is not a rate; give --fs HZ")
    if fs > MAX_FS:
        given = f"--fs {fs:g}" if opts.fs is not None else f"{files[0]}: sampling rate {fs:g} Hz"
        raise ImportFailure(f"{given}: more than the board protocol carries (STATUS fs: at most {MAX_FS:,} Hz); "
                            "check --fs")
    if fs != round(fs):
        raise ImportFailure(f"{files[0]}: sampling rate {fs:g} Hz; the board protocol carries a whole "
                            "number of Hz (--fs); resample the recording or give --fs with the rate rounded")
    if opts.fs is not None and layout.file_fs is not None and opts.fs != layout.file_fs:
        notes.append(f"fs {opts.fs:g} Hz from --fs (the file says {layout.file_fs:g} Hz)")
    notes += _short_snapshots(snaps, opts)
    snaps, start = retimed(snaps, origins, files, opts, fs, own_times, "date" if dated else "day" if clock else "",
                            notes)
    rec = Recording(fs=int(round(fs)), samples=stores[0], names=layout.names, snapshots=snaps,
                    sources=[str(f) for f in files], source_units=layout.units, ppr=board_ppr(opts.ppr), notes=notes,
                    source_start=start)
    if layout.tacho is not None:
        _tacho(rec, np.concatenate(tacho_pieces), layout.columns[layout.tacho], opts)
    _speed(rec, opts, rpms[0] if rpms else None, layout.tacho is not None)
    differ = _speeds_differ(rpms) if opts.rpm is None and layout.tacho is None else []
    rec.notes += differ
    rec.rpm_differs = bool(differ)
    return rec


def _whole_recordings(whole: list[tuple[str, int]], path: str, n: int, files: list[str],
                      opts: ImportOptions) -> None:
    """Refuse a second file of many snapshots of its own (``n``; ``whole``: those read before):
    such a file is a whole recording (FEMTO's archive of a bearing's life), and files of several
    machines laid end to end would be taken as one machine's history, a commissioning on its
    first share judging the others; ``--join-recordings`` lays them end to end on purpose. A
    directory of one-snapshot files (the IMS rig's, FEMTO's CSVs) is one recording."""
    if n < 2 or opts.join_recordings:
        return
    whole.append((path, n))
    if len(whole) < 2:
        return
    (first, n0), (second, n1) = whole
    stem = Path(first).stem
    raise ImportFailure(
        f"{Path(first).name} ({n0:,} snapshots) and {Path(second).name} ({n1:,}) each hold a whole recording; "
        f"import each of the {len(files)} files on its own (cmsensord import {first} ... --out {stem}.bin), "
        "or give --join-recordings to lay them end to end as one machine's history")


def _speeds_differ(rpms: list[tuple[float, str]]) -> list[str]:
    """A note when the files give speeds more than 1 % apart (CWRU's files, one a load): the
    sidecar keeps the first's."""
    if not rpms or max(r for r, _ in rpms) <= 1.01 * min(r for r, _ in rpms):
        return []
    other = [(r, name) for r, name in rpms if abs(r - rpms[0][0]) > 0.01 * rpms[0][0]]
    listed = ", ".join(f"{name} {r:g} rpm" for r, name in other[:3]) + (", ..." if len(other) > 3 else "")
    return [f"the files give different speeds ({rpms[0][1]} {rpms[0][0]:g} rpm; {listed}): the capture keeps "
            f"{rpms[0][0]:g} rpm; import each speed on its own, or give --rpm"]


def _speed(rec: Recording, opts: ImportOptions, rpm_file: tuple[float, str] | None, tacho: bool) -> None:
    """The recording's speed: ``--rpm`` (checked: at most one edge a sample), else the one a file
    gave; a note when ``--ppr`` is more than the board carries and a tacho is made."""
    if rec.ppr != opts.ppr and (tacho or opts.rpm is not None):
        rec.notes.append(f"--ppr {opts.ppr}: the board protocol carries at most {MAX_PPR} pulses a revolution: "
                         f"{rec.ppr} a revolution (one edge in {opts.ppr // rec.ppr}, at the same angles)")
    if opts.rpm is not None and opts.rpm * rec.ppr > 60.0 * rec.fs:
        raise ImportFailure(f"--rpm {opts.rpm:g}: more than one tacho edge a sample at {rec.ppr} a revolution "
                            f"(at most {60.0 * rec.fs / rec.ppr:g} rpm at {rec.fs:g} Hz); check --rpm and --ppr")
    if opts.rpm is not None:
        rec.rpm, rec.rpm_source, rec.tacho_source, rec.tacho_from = opts.rpm, "--rpm", "rpm", "rpm"
    elif rpm_file is not None and rec.rpm is None:
        rec.rpm, rec.rpm_source = rpm_file


def _tacho_column(t: Table, col: int, fs: float, opts: ImportOptions) -> np.ndarray:
    """A file's tacho or speed column, float64, checked finite (and a speed of at most one
    edge a sample at the import's rate ``fs``)."""
    x = (t.data[:, :, col].astype(np.float64).reshape(-1) - t.zero) * t.gain
    option = "--speed-column" if opts.speed_column else "--tacho-column"
    bad = ~np.isfinite(x)
    if bad.any():
        raise ImportFailure(f"{t.path}: {t.kind} {t.columns[col]!r} ({option}) has {int(bad.sum())} missing or "
                            f"non-finite value(s) (first at sample {int(np.argmax(bad))}); clean the file")
    top = float(np.abs(x).max()) if x.size else 0.0
    ppr = board_ppr(opts.ppr)
    if opts.speed_column and top * ppr > 60.0 * fs:
        raise ImportFailure(f"{t.path}: speed column {t.columns[col]!r} reaches {top:g} rpm, "
                            f"more than one tacho edge a sample at {ppr} a revolution (at most "
                            f"{60.0 * fs / ppr:g} rpm at {fs:g} Hz); check the column's unit and --ppr")
    return x


def _tacho(rec: Recording, column: np.ndarray, name: str, opts: ImportOptions) -> None:
    """The tacho edges of a pulse column, or of a speed column (rpm; its median also the
    sidecar's ``rpm``)."""
    bounds = [(s.start, s.length) for s in rec.snapshots]
    if opts.speed_column:
        rec.tacho_edges = speed_edges(column, bounds, rec.fs, rec.ppr)
        rec.tacho_source, rec.tacho_from = name, "speed"
        median = float(np.median(column))       # a machine stopped most of the time: no speed
        rec.rpm, rec.rpm_source = (median, f"column {name} (median)") if median > 0 else (None, None)
    else:
        rec.tacho_edges = every_kth(pulse_edges(column, bounds, opts.tacho_threshold), bounds, opts.ppr // rec.ppr)
        rec.tacho_source, rec.tacho_from = name, "pulses"
