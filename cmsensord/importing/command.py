"""``cmsensord import SRC... --out CAPTURE``: the sub-command's options, run and summary.

    cmsensord import femto/Bearing1_1.npz --unit mg --channels 0 --names horizontal --out b11.bin
    cmsensord import ims/NA.mat --fs 20480 --unit g --snapshot-len 20480 --out na.bin
  cmsensord import IMS/2nd_test --fs 20480 --unit g --channels 0 --out b1.bin   (files named by time)

Errors the user can cause end in one line, ``cmsensord import: FILE: what; fix``,
and exit status 2; nothing is written then. Ctrl-C is one line too, saying what it left at
``--out``, and exit status 130. A progress bar shows on a terminal. Each channel's
mean is taken out (:mod:`.dc`, one summary line a channel) unless ``--keep-dc``. A channel whose
range leaves snapshots (or seconds) under 10 counts RMS gets one WARNING line (:mod:`.quantisation`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from cmsensord.argtypes import comma_list, count, nonnegative, nonzero, positive, real
from cmsensord.errors import EXIT_INTERRUPTED, EXIT_USAGE
from cmsensord.out_paths import not_a_file, overwritten_input
from cmsensord.terminal_bar import Bar

from .adc import ADC_MAX, OFFSET, nice_range
from .blocks import choose_block_len, plan_blocks, remainder_note
from .capture_writer import choose_ranges, sidecar_path, write_capture
from .dc import dc_lines, remove_dc
from .errors import CHOOSE, ImportFailure
from .options import ImportOptions
from .quantisation import LevelTally, quantised_lines
from .recording import Recording
from .samples import MEMORY_MB
from .sources import build_recording, collect_files
from .units import UNITS, G, InG, unit_of

__all__ = ["add_import_parser", "run_import", "options_from_args"]

_EXAMPLES = """\
examples:
  cmsensord import rec.wav --unit g --out rec.bin                   (fs from the WAV)
  cmsensord import log.csv --fs 25600 --channels acc_x,acc_y --unit g --out log.bin
  cmsensord import daq.csv --unit g --out daq.bin                   (fs from its time column, 'Time (s)')
  cmsensord import femto/Bearing1_1.npz --unit mg --channels 0 --names horizontal --out b11.bin
  cmsensord import 'Bearing1_1/acc_*.csv' --fs 25600 --channels 4 --unit g --snapshot-interval 10 --out b11.bin
  cmsensord import ims/NA.mat --fs 20480 --unit g --snapshot-len 20480 --out na.bin
  cmsensord import IMS/2nd_test --fs 20480 --unit g --channels 0 --out b1.bin   (files named by time)
Columns and channels count from 0. The sidecar CAPTURE.json (b11.bin.json) lists the snapshots
(board second, length, % of the record, original time and gap), units and scales."""


def _units(text: str) -> tuple[str, ...]:
    """'g' or 'g,Pa' -> units of UNITS; as files and configurations spell them too
    ('m/s^2', 'm/s²', 'G': :func:`~.units.unit_of`)."""
    given = comma_list(text)
    units = tuple(u if u in UNITS else unit_of(u) or "" for u in given)
    bad = [g for g, u in zip(given, units) if not u]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown unit {bad[0]!r}; choose from {', '.join(UNITS)} (one, or one "
                                         "per channel: g,Pa)")
    return units


def _numbers(kind):
    """'2' or '2,0.5' -> numbers of ``kind`` (an argparse type)."""
    return lambda text: tuple(kind(item) for item in comma_list(text))


def _ranges(text: str) -> tuple[float, ...]:
    """'50', '5g', '50,100' -> values in the channels' units (m/s² for '5g': :class:`InG`)."""
    out: list[float] = []
    for item in comma_list(text):
        g = item.lower().endswith("g")
        v = positive(item[:-1] if g else item.removesuffix("m/s2"))
        out.append(InG(v * G) if g else v)
    return tuple(out)


_SEPARATOR_NAMES = {"tab": "\t", "\\t": "\t", "comma": ",", "semicolon": ";", "space": "whitespace",
                    "whitespace": "whitespace"}


def add_import_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "import", help="turn a recording from another data logger (WAV, CSV, LVM, NPY/NPZ, MAT, TDMS, "
                       "snapshot files) into a capture for replay",
        description="Turn a recording from another data logger into a capture of the board's "
                    "protocol (RAW mode at the recording's own rate, or RMS mode), with a sidecar "
                    "OUT.json that records the snapshots and their gaps.",
        epilog=_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("src", nargs="*", metavar="SRC",
                   help="file(s), a directory of snapshot files, or a quoted glob pattern")
    p.add_argument("--out", dest="imp_out", required=True, metavar="CAPTURE", help="capture file to write")
    p.add_argument("--glob", dest="imp_glob", action="append", default=[], metavar="PATTERN",
                   help="snapshot files matching PATTERN (repeatable)")
    p.add_argument("--order", dest="imp_order", choices=("name", "mtime", "given"), default="name",
                   help="order of snapshot files: natural name order (default), modification time, "
                        "or as given")
    p.add_argument("--mode", dest="imp_mode", choices=("raw", "rms"), default="raw",
                   help="RAW frames at the recording's rate (default) or 100 Hz RMS frames")
    p.add_argument("--fs", dest="imp_fs", type=positive, metavar="HZ",
                   help="sampling rate; required for CSV/NPY/MAT files that do not carry it")
    p.add_argument("--channels", "--columns", dest="imp_channels", type=comma_list, metavar="LIST",
                   help="columns/channels to import, by index from 0 or by name (default: all but "
                        "the tacho column, at most 8)")
    p.add_argument("--names", dest="imp_names", type=comma_list, metavar="LIST", help="channel names")
    p.add_argument("--array", dest="imp_array", type=comma_list, metavar="NAME[,NAME]",
                   help="the array(s) of an .npz file, side by side; a name may be a pattern (*_x)")
    p.add_argument("--variable", dest="imp_variable", type=comma_list, metavar="NAME[,NAME]",
                   help="the variable(s) of a .mat file, side by side; a name may be a pattern "
                        "(*_DE_time) or a struct's field (bearing.gs)")
    p.add_argument("--separator", dest="imp_separator", metavar="SEP",
                   help="CSV separator: ',', ';', tab, whitespace, ... (default: detected)")
    hdr = p.add_mutually_exclusive_group()
    hdr.add_argument("--header", dest="imp_header", action="store_const", const=True,
                     help="the CSV's first line names the columns (default: detected)")
    hdr.add_argument("--no-header", dest="imp_header", action="store_const", const=False,
                     help="the CSV has no header line")
    p.add_argument("--unit", dest="imp_unit", type=_units, default=None, metavar="UNIT[,UNIT]",
                   help=f"unit of the values, one or one per channel: {', '.join(UNITS)} (Pa: a microphone; "
                        "default: the units the file gives its columns, in a units line, the column names or "
                        "TDMS unit_string, or a name's ending (acc_mg); else m/s2; V needs --sensitivity)")
    p.add_argument("--sensitivity", dest="imp_sensitivity", type=_numbers(positive), metavar="MV_PER_G[,...]",
                   help="accelerometer sensitivity in mV/g, for the channels in V (one, or one per channel)")
    p.add_argument("--scale-factor", dest="imp_scale_factor", type=_numbers(nonzero),
                   default=(1.0,), metavar="X[,X]",
                   help="multiply the values by X first, one or one per channel (WAV PCM: the value at full scale)")
    p.add_argument("--range", dest="imp_range", type=_ranges, metavar="R",
                   help="12-bit full scale +-R in m/s2 (or e.g. 5g), one or one per channel "
                        "(default: max |x| x 1.25, rounded up to a 1-1.2-1.5-2-2.5-3-4-5-6-8 value)")
    p.add_argument("--block-len", dest="imp_block_len", type=count(1, 0xFFFF), metavar="N",
                   help="samples per block (default fs/100, rounded: 100 blocks a second)")
    p.add_argument("--snapshot-len", dest="imp_snapshot_len", type=count(1, 1 << 40), metavar="N",
                   help="split each file's samples into snapshots of N (e.g. 20480 for IMS)")
    p.add_argument("--snapshot-interval", dest="imp_snapshot_interval", type=positive, metavar="S",
                   help="seconds between snapshot starts in the original recording (for the sidecar; "
                        "default: the files' own times, or the dates and times in their names)")
    tach = p.add_mutually_exclusive_group()
    tach.add_argument("--tacho-column", dest="imp_tacho_column", metavar="COL",
                      help="a tacho pulse column/channel (index or name): rising crossings are edges")
    tach.add_argument("--speed-column", dest="imp_speed_column", metavar="COL",
                      help="a column/channel of shaft speed in rpm (index or name): TACHO frames with --ppr "
                           "edges a revolution, the speed integrated")
    tach.add_argument("--rpm", dest="imp_rpm", type=positive, metavar="RPM",
                      help="constant shaft speed: TACHO frames with --ppr edges a revolution")
    p.add_argument("--tacho-threshold", dest="imp_tacho_threshold", type=real, metavar="X",
                   help="pulse threshold (default: halfway between the column's 1st and 99th percentile)")
    p.add_argument("--keep-dc", dest="imp_keep_dc", action="store_true",
                   help="keep each channel's mean (DC offset) in the capture; by default it is taken out, as "
                        "the board's offset calibration does: each snapshot's own, or the whole recording's")
    p.add_argument("--memory-mb", dest="imp_memory_mb", type=nonnegative, default=MEMORY_MB, metavar="MB",
                   help=f"hold at most MB of samples in memory (default {MEMORY_MB:g}); a longer recording "
                        "waits on disk beside --out while the capture is written (8 bytes a sample a "
                        "channel)")
    p.add_argument("--join-recordings", dest="imp_join", action="store_true",
                   help="lay several files of many snapshots each (whole recordings) end to end as one "
                        "machine's history; without it such files are refused, to be imported one by one")
    p.add_argument("--ppr", dest="imp_ppr", type=count(1, 1 << 16), default=1, metavar="N",
                   help="tacho pulses per revolution (default 1); above 255 (an encoder's) every k-th "
                        "edge is kept, 255 or fewer a revolution")
    return p


def options_from_args(args: argparse.Namespace) -> ImportOptions:
    sep = args.imp_separator
    if sep is not None:
        sep = _SEPARATOR_NAMES.get(sep.lower(), sep)
        if len(sep) != 1 and sep != "whitespace":
            raise ImportFailure(f"--separator {args.imp_separator!r}: give one character, tab or whitespace")
    return ImportOptions(
        out=args.imp_out, mode=args.imp_mode, fs=args.imp_fs, channels=args.imp_channels,
        names=args.imp_names, array=args.imp_array, variable=args.imp_variable, separator=sep,
        header=args.imp_header, unit=args.imp_unit, sensitivity=args.imp_sensitivity,
        scale_factor=args.imp_scale_factor, full_scale=args.imp_range, block_len=args.imp_block_len,
        snapshot_len=args.imp_snapshot_len, snapshot_interval=args.imp_snapshot_interval,
        order=args.imp_order, tacho_column=args.imp_tacho_column, speed_column=args.imp_speed_column,
        tacho_threshold=args.imp_tacho_threshold, ppr=args.imp_ppr, rpm=args.imp_rpm,
        keep_dc=args.imp_keep_dc, memory_mb=args.imp_memory_mb, join_recordings=args.imp_join)


#: peaks past these are more than a machine's accelerometer or microphone measures: a unit
#: mistaken, most likely mg given as g (1000 x)
IMPLAUSIBLE_G = 1000.0
IMPLAUSIBLE_PA = 2000.0     # 160 dB SPL


def _implausible(name: str, peak: float, unit: str) -> list[str]:
    """A WARNING line when a channel's peak is more than a machine's sensor sees."""
    if unit == "Pa":
        if peak <= IMPLAUSIBLE_PA:
            return []
        return [f"  WARNING {name}: peak {peak:.4g} Pa ({20 * math.log10(peak / 2e-5):.0f} dB SPL), more than a "
                "microphone at a machine hears: is --unit right?"]
    if peak <= IMPLAUSIBLE_G * G:
        return []
    return [f"  WARNING {name}: peak {peak:.4g} m/s2 ({peak / G:,.0f} g), more than an accelerometer on a machine "
            "measures: is --unit right (values in mg given as g read 1000 x)?"]


def _report(meta: dict, rec: Recording, out: str, size: int, notes: list[str],
            quiet: dict[int, str]) -> list[str]:
    C = len(meta["channel_names"])
    n_snap = len(meta["snapshots"])
    lines = [f"capture: {out} ({size:,} bytes, {meta['frames']:,} frames): "
             f"{meta['mode'].upper()}, {C} channel(s), fs {meta['fs']} Hz, block {meta['block_len']} "
             f"({meta['blocks_per_s']:g} blocks/s), {meta['board_seconds']:.2f} s of board time"
             + (f" from {n_snap} snapshots" if n_snap > 1 else "")]
    peaks = rec.peak
    dc = dc_lines(rec)
    for c, name in enumerate(meta["channel_names"]):
        fs_, sc, u = meta["full_scale"][c], meta["scale"][c], rec.units[c]
        line = f"  {name}: full scale +-{fs_:g} {u} ({sc:.4g} {u} a count), peak {peaks[c]:.4g} {u}"
        nclip, lost = meta["clipped_samples"][c], meta["missing_blocks"][c]
        lines.append(line + (", no clipping" if not nclip else "")
                     + (f", {lost:,} block(s) left out for missing samples" if lost else ""))
        lines += dc[c:c + 1]
        if lost * 10 >= meta["blocks"] and C > 1:
            lines.append(f"  WARNING {name}: its missing samples leave out {100 * lost / meta['blocks']:.0f} % of the "
                         f"blocks, every channel's (a frame holds them all); leave it out ({CHOOSE}) to keep them")
        lines += _implausible(name, peaks[c], u)
        lines += [quiet[c]] if c in quiet and peaks[c] > 0 else []      # a constant: said below
        if not peaks[c] > 0:
            same = "0" if not rec.samples.peak[c] > 0 else "the same, a constant offset"
            lines.append(f"  WARNING {name}: every value is {same} (no sensor on it?): calibrate cannot learn it; "
                         "leave it out with --channels")
        if nclip:
            lines.append(f"  WARNING {name}: {nclip} sample(s) in {meta['clipped_blocks'][c]} block(s) "
                         f"clipped at +-{fs_:g} {u} (counts 0/{ADC_MAX}); those blocks carry the "
                         f"clipped flag; --range {nice_range(peaks[c]):g} avoids it")
    if meta["tacho"]:
        if meta["tacho_from"] == "rpm":
            what = f"constant {meta['rpm']:g} rpm"
        elif meta["tacho_from"] == "speed":
            what = f"speed column {meta['tacho']} " + (f"(median {meta['rpm']:g} rpm)" if meta["rpm"] else
                                                          "(stopped half the time or more: no median speed)")
        else:
            what = f"column {meta['tacho']}"
        lines.append(f"  tacho: {what}, {meta['tacho_edges']} edge(s), {meta['ppr']} a revolution")
    elif meta["rpm"]:
        lines.append(f"  speed: {meta['rpm']:g} rpm from {meta['rpm_source']} (no TACHO frames: replay takes it "
                     f"as indicators.rpm{', unless the files differ' if meta.get('rpm_differs') else ''}; --rpm "
                     f"{meta['rpm']:g} also sends TACHO frames)")
    lines += [f"  note: {n}" for n in notes]
    lines.append(f"  sidecar: {sidecar_path(out)} (sources, snapshots, gaps, scales)")
    return lines


def _run(opts: ImportOptions, srcs: list[str], globs: list[str]) -> int:
    left: list[str] = []                    # what a directory's files left out
    files = collect_files(srcs, globs, opts.order, left)
    if Path(opts.out).is_dir():
        raise ImportFailure(f"{opts.out}: is a directory; give --out a file name, e.g. "
                            f"{Path(opts.out) / 'capture.bin'}")
    same = overwritten_input(opts.out, files) or not_a_file(opts.out, "the capture")
    if same:
        raise ImportFailure(same)
    bar = Bar(len(files), f"import: reading {len(files)} file(s)")
    try:
        rec = build_recording(files, opts, progress=bar)
    finally:
        bar.close()
    with rec.samples:
        return _write(rec, opts, files, left)


def _one_or_all(values: tuple[float, ...] | None) -> float | list[float] | None:
    """An option given once as its value, one per channel as the list (the sidecar's)."""
    return values if values is None else values[0] if len(values) == 1 else list(values)


def _refuse_empty_channels(rec: Recording) -> None:
    """An ImportFailure when a channel has no value at all (every one missing): the board's
    frames hold every channel, so its missing blocks would leave out every other channel's."""
    empty = [name for name, n in zip(rec.names, rec.samples.missing) if n == rec.samples.n_samples]
    if empty and rec.samples.n_samples:
        kept = [name for name in rec.names if name not in empty]
        keep = f"import only {', '.join(kept)} ({CHOOSE})" if kept else "check the files' channels"
        raise ImportFailure(f"{', '.join(empty)}: no value in the recording (every one NaN, inf or empty): "
                            f"each frame holds every channel, so no block could be written; {keep}")


def _write(rec: Recording, opts: ImportOptions, files: list[str], left: list[str]) -> int:
    _refuse_empty_channels(rec)
    L, note = choose_block_len(rec.fs, opts.block_len, opts.mode)
    plan = plan_blocks(rec, L)
    notes = left + list(rec.notes) + ([note] if note else [])
    rem = remainder_note(rec, plan)
    if rem:
        notes.append(rem)
    if plan.n_blocks == 0:
        longest = max(s.length for s in rec.snapshots)
        if opts.snapshot_len:
            raise ImportFailure(f"--snapshot-len {opts.snapshot_len}: snapshots of {longest} sample(s) fill no "
                                f"{L}-sample block; give a --snapshot-len of {L} or more, or a smaller --block-len")
        what = f"{rec.n_samples} sample(s)" if len(rec.snapshots) == 1 else f"snapshots of at most {longest} sample(s)"
        raise ImportFailure(f"{files[0]}: {what} fill no {L}-sample block; give a smaller --block-len")
    if not opts.keep_dc:
        remove_dc(rec)                      # before the ranges: they fit the signal without its mean
    full_scale = choose_ranges(rec, opts.full_scale)
    extra = {"scale_factor": _one_or_all(opts.scale_factor), "sensitivity_mv_per_g": _one_or_all(opts.sensitivity),
             "offset_counts": OFFSET, "notes": notes}
    bar = Bar(plan.n_blocks, f"import: writing {Path(opts.out).name}")
    tally = LevelTally(rec.n_channels, plan, rec.fs)
    try:
        meta = write_capture(rec, plan, opts.out, mode=opts.mode, full_scale=full_scale, extra=extra,
                             progress=bar, tally=tally)
    finally:
        bar.close()
    size = Path(opts.out).stat().st_size
    places = [f"{s['source']} at {s['pct_of_record']:.3g} % of the record" for s in meta["snapshots"]]
    quiet = quantised_lines(tally, meta["channel_names"], rec.units, full_scale, meta["scale"], places,
                            L / rec.fs, opts.mode)
    print("\n".join(_report(meta, rec, opts.out, size, notes, quiet)), file=sys.stderr)
    return 0


def run_import(args: argparse.Namespace) -> int:
    """The ``import`` sub-command: 0 on success, 2 with a one-line message on a usage or input
    error, 130 with one on Ctrl-C (what is at ``--out`` then: nothing, the file there before, or
    the capture complete when the Ctrl-C came after it was written)."""
    before = _file_id(args.imp_out)
    try:
        return _run(options_from_args(args), list(args.src), list(args.imp_glob))
    except ImportFailure as exc:
        print(f"cmsensord import: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        out, now = args.imp_out, _file_id(args.imp_out)
        left = (f"nothing written ({out} not made)" if now is None else
                f"nothing written ({out} left as it was)" if now == before else
                f"after {out} was written: it and its sidecar {sidecar_path(out)} are complete")
        print(f"cmsensord import: interrupted (Ctrl-C): {left}", file=sys.stderr)
        return EXIT_INTERRUPTED


def _file_id(path: str) -> tuple[int, int] | None:
    """(device, inode) of the file at ``path`` (None: none): a capture written there is a new file."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino
