#!/usr/bin/env python3
"""Benchmark of ``cmsensord import`` over a directory of snapshot files: wall time, CPU
seconds and peak resident memory as the recording grows.

Writes N one-second snapshot files of four channels at 20,480 Hz, as the IMS rig's
(text tables of numbers, tab-separated, three decimals, named by date and time), then runs
``python -m cmsensord import DIR --fs 20480 --unit g --out ...`` as a user would, once per
length, and prints per length the files, the recording's float64 samples (MB), the
capture's size, wall and CPU seconds and the import process's peak resident memory. The
same memory for every length shows that it is bounded (``--memory-mb``, default 64, then
one file). ``--wav-minutes M`` (repeatable) also imports one long WAV file of M minutes, as
a field recorder writes it (48 kHz, stereo, 16-bit): its memory should not grow with its
length either; ``--csv-minutes M`` one long CSV (a time column and three channels at
25.6 kHz); ``--tdms-minutes M`` one long TDMS file and ``--npz-minutes M`` one long
uncompressed .npz (four float64 channels at 25.6 kHz each). The long files' table also gives
the import's peak anonymous memory (its own, not the pages of the files it maps). Peak RSS
is each import's own VmHWM. ``--tree LABEL=DIR`` (repeatable) runs another checkout's code
on the same files, side by side.

    python bench/bench_import.py [--files 60 240] [--wav-minutes 2 10] [--csv-minutes 2 10]
                                 [--tdms-minutes 2 10] [--npz-minutes 2 10] [--memory-mb 64]
                                 [--tree before=DIR] [--keep DIR]
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_rms import trees  # noqa: E402  (each checkout compiled to .pyc, as installed)

FS = 20480
CHANNELS = 4


def write_files(d: Path, n: int) -> None:
    """``n`` IMS-like snapshot files in ``d``, ten minutes apart by their names."""
    d.mkdir(parents=True)
    rng = np.random.default_rng(0)
    t = dt.datetime(2004, 2, 12, 10, 32, 39)
    for k in range(n):
        name = (t + dt.timedelta(minutes=10 * k)).strftime("%Y.%m.%d.%H.%M.%S")
        np.savetxt(d / name, 0.1 * rng.standard_normal((FS, CHANNELS)), fmt="%.3f", delimiter="\t")


WAV_FS = 48000


def write_wav(path: Path, minutes: float) -> None:
    """A stereo 16-bit WAV of ``minutes`` at 48 kHz, written a minute at a time."""
    import wave

    rng = np.random.default_rng(1)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(2)
        w.setsampwidth(2)
        w.setframerate(WAV_FS)
        for _ in range(int(round(minutes))):
            w.writeframes((rng.standard_normal((60 * WAV_FS, 2)) * 3000).astype("<i2").tobytes())


CSV_FS = 25600
LOGGER_FS = 25600


def write_tdms(path: Path, minutes: float) -> None:
    """A logger's TDMS file of ``minutes``: four float64 channels at 25.6 kHz, a segment a second."""
    import nptdms

    rng = np.random.default_rng(3)
    wave = {"wf_increment": 1.0 / LOGGER_FS, "wf_start_time": np.datetime64("2024-03-05T10:15:00")}
    with nptdms.TdmsWriter(str(path)) as w:
        for k in range(int(round(minutes * 60))):
            x = np.round(0.1 * rng.standard_normal((4, LOGGER_FS)), 5)
            w.write_segment([nptdms.ChannelObject("Vibration", f"acc{c}", x[c], wave if k == 0 else {})
                             for c in range(4)])


def write_npz(path: Path, minutes: float) -> None:
    """An .npz of ``minutes`` as ``np.savez`` stores it (uncompressed): ``acc`` (samples, 4) float64
    at 25.6 kHz and ``fs``, written a minute at a time into the archive's member."""
    import zipfile

    rng = np.random.default_rng(4)
    n = int(round(minutes * 60)) * LOGGER_FS
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
        with z.open("acc.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (n, 4)})
            for _ in range(int(round(minutes))):
                f.write(np.round(0.1 * rng.standard_normal((60 * LOGGER_FS, 4)), 5).tobytes())
        with z.open("fs.npy", "w") as f:
            np.lib.format.write_array(f, np.array(float(LOGGER_FS)))


def write_csv(path: Path, minutes: float) -> None:
    """A CSV of ``minutes`` at 25.6 kHz: ``Time (s)`` and three channels in g, a minute at a time."""
    rng = np.random.default_rng(2)
    with open(path, "w") as f:
        f.write("Time (s),ax,ay,az\n")
        for k in range(int(round(minutes))):
            t = (k * 60 * CSV_FS + np.arange(60 * CSV_FS)) / CSV_FS
            np.savetxt(f, np.c_[t, 0.1 * rng.standard_normal((t.size, 3))], fmt=["%.6f", "%.4f", "%.4f", "%.4f"],
                       delimiter=",")


def run_import(src: Path, out: Path, tree: Path, memory_mb: float | None, *how: str) -> dict:
    """One ``cmsensord import SRC HOW`` in a child process (HOW: the IMS-like files' options by
    default): wall s, CPU s, peak RSS MB, capture MB."""
    how = how or ("--fs", str(FS), "--unit", "g", "--block-len", "2048")
    args = [sys.executable, "-m", "cmsensord", "import", str(src), *how, "--out", str(out)]
    if memory_mb is not None:
        args += ["--memory-mb", f"{memory_mb:g}"]
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.monotonic()
    p = subprocess.Popen(args, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err: list[bytes] = []
    reader = threading.Thread(target=lambda: err.append(p.stderr.read() if p.stderr else b""))
    reader.start()
    anon = peak = 0
    while True:
        pid, status, usage = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        anon = max(anon, _status_kb(p.pid, "RssAnon:"))
        peak = max(peak, _status_kb(p.pid, "VmHWM:"))     # ru_maxrss starts at this process's peak
        time.sleep(0.02)
    wall = time.monotonic() - t0
    reader.join()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"import failed ({tree}):\n{b''.join(err).decode()}")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "rss_mb": peak / 1024,
            "anon_mb": anon / 1024, "capture_mb": out.stat().st_size / 1e6}


def measure(args: argparse.Namespace, src: Path, write, length: float, what: str,
            *how: str) -> list[tuple[str, dict]]:
    """(label, :func:`run_import`'s result) of importing ``src`` with each tree (``args.tree``),
    ``src`` written first (``write(src, length)``) unless it is there."""
    if not src.exists():
        print(f"writing {what} ...", file=sys.stderr, flush=True)
        write(src, length)
    return [(label, run_import(src, src.parent / f"{src.name}_{label or 'this'}.bin", tree,
                               args.memory_mb if tree == ROOT else None, *how)) for label, tree in trees(args.tree)]


def _status_kb(pid: int, key: str) -> int:
    """A field of the process's /proc status now, kB: ``RssAnon:`` its anonymous resident memory
    (its own, not pages of files it maps), ``VmHWM:`` its peak resident memory since its exec."""
    try:
        with open(f"/proc/{pid}/status") as f:
            return next((int(line.split()[1]) for line in f if line.startswith(key)), 0)
    except OSError:
        return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, nargs="+", default=[60, 240], help="recording lengths, in files")
    ap.add_argument("--wav-minutes", type=float, nargs="*", default=[],
                    help="also one long stereo WAV of these lengths, in minutes")
    ap.add_argument("--csv-minutes", type=float, nargs="*", default=[],
                    help="also one long CSV (a time column, 3 channels at 25.6 kHz) of these lengths, in minutes")
    ap.add_argument("--tdms-minutes", type=float, nargs="*", default=[],
                    help="also one long TDMS file (4 channels at 25.6 kHz, the tdms extra) of these lengths")
    ap.add_argument("--npz-minutes", type=float, nargs="*", default=[],
                    help="also one long uncompressed .npz (4 channels at 25.6 kHz) of these lengths")
    ap.add_argument("--memory-mb", type=float, help="passed to this checkout's import (default: its own)")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR",
                    help="also run another checkout's code (e.g. before=../old)")
    ap.add_argument("--keep", type=Path, help="write the files and captures here and keep them")
    args = ap.parse_args()
    base = args.keep or Path(tempfile.mkdtemp(prefix="bench_import_"))
    rows: list = []
    long_rows: list = []
    try:
        for n in sorted(args.files):
            rows += [(label, n, r) for label, r in measure(args, base / f"files_{n}", write_files, n,
                                                             f"{n} snapshot files")]
        for kind, minutes, write, fs, channels, how in (
                ("CSV", args.csv_minutes, write_csv, CSV_FS, 3, ("--unit", "g")),
                ("WAV", args.wav_minutes, write_wav, WAV_FS, 2, ("--unit", "g", "--scale-factor", "10")),
                ("TDMS", args.tdms_minutes, write_tdms, LOGGER_FS, 4, ("--unit", "g")),
                ("NPZ", args.npz_minutes, write_npz, LOGGER_FS, 4, ("--unit", "g"))):
            for m in sorted(minutes):
                src = base / f"long_{m:g}.{kind.lower()}"
                found = measure(args, src, write, m, f"a {m:g}-minute {kind}", *how)
                long_rows += [(kind, label, m, src.stat().st_size / 1e6, m * 60 * fs * channels * 8 / 1e6, r)
                              for label, r in found]
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    samples_mb = {n: n * FS * CHANNELS * 8 / 1e6 for n in args.files}
    print(f"cmsensord import of N IMS-like text files (1 s, {CHANNELS} channels at {FS} Hz each)")
    print("| code | files | samples MB (float64) | capture MB | wall s | CPU s | peak RSS MB |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for label, n, r in rows:
        print(f"| {label or 'this'} | {n} | {samples_mb[n]:.0f} | {r['capture_mb']:.1f} | {r['wall_s']:.1f} | "
              f"{r['cpu_s']:.1f} | {r['rss_mb']:.0f} |")
    if long_rows:
        print(f"\ncmsensord import of one long file: a stereo 16-bit WAV at {WAV_FS} Hz, a CSV of a time column "
              f"and 3 channels at {CSV_FS} Hz, a TDMS file and an .npz of 4 float64 channels at {LOGGER_FS} Hz "
              "('own MB': peak anonymous memory, not pages of files it maps)")
        print("| file | code | minutes | file MB | samples MB (float64) | capture MB | wall s | CPU s | peak RSS MB "
              "| own MB |")
        print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for kind, label, m, file_mb, samples_mb, r in long_rows:
            print(f"| {kind} | {label or 'this'} | {m:g} | {file_mb:.0f} | {samples_mb:.0f} | {r['capture_mb']:.1f} | "
                  f"{r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['rss_mb']:.0f} | {r['anon_mb']:.0f} |")


if __name__ == "__main__":
    main()
