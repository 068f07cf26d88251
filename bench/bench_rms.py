#!/usr/bin/env python3
"""Benchmark of the RMS chain: decode + AKF banks + MCAP, as `cmsensord replay` runs it.

Builds RMS-mode captures with firmware_sim (1, 4 and 8 channels), replays each
in a fresh subprocess (`python -m cmsensord replay`) and prints a table of
real-time factor, throughput, CPU time and peak RSS, with the default logging
and with the per-observation AKF trace on.  Then, in the same run, times the
bank of 10 AKFs against the same bank written with one filterpy KalmanFilter
per filter (the peer; `pip install filterpy` in the benchmark's environment
only) on the same input, and checks both give the same estimates.

    python bench/bench_rms.py [--seconds 600] [--peer-seconds 60] [--channels 4] [--no-trace]
                              [--no-peer] [--tree before=DIR] [--repeat 3] [--scenario healthy]
                              [--preload]

``--tree LABEL=DIR`` (repeatable) replays each capture with another checkout's code too
(its C kernels built in place), interleaved with this one: before/after figures of one run.
``--repeat N`` replays each capture N times per code and shows the best (a shared machine
only slows a run down).

Figures are ratios measured side by side in one run; machines here are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def make_capture(path: Path, channels: int, seconds: float, scenario: str = "degrading") -> None:
    """An RMS capture of ``seconds`` of firmware_sim's ``scenario`` (seed 1)."""
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario(scenario, n_channels=channels, duration_s=seconds, seed=1)
    Board(sc, BoardConfig(n_channels=channels)).write_capture(path, seconds)


#: what the command line's parser imported on every command before `cmsensord replay` had a
#: parser of its own (the import, report and operator commands' modules): with ``preload``,
#: loaded before the replay is timed, as the rest of the imports are (without .pyc files,
#: PYTHONDONTWRITEBYTECODE=1, each is compiled: ~0.05 s); for older code in ``--tree``
PRELOAD = "import cmsensord.importing.command, cmsensord.report.command, cmsensord.service.operator\n"
#: makes the compiled kernels unimportable in the replay's interpreter (tests/test_no_compiler.py)
NO_KERNELS = ("for m in ('cmsensord.dsp._akfkernel', 'cmsensord.dsp._trackerkernel', 'cmsensord._wirekernel'): "
              "sys.modules[m] = None\n")


def replay_in_subprocess(capture: Path, out: Path, trace: bool, tree: Path = ROOT, kernels: bool = True,
                         preload: bool = False) -> dict:
    """Run `cmsensord replay` in a fresh interpreter; time the replay itself (not the imports).

    ``tree``: the checkout whose code runs (another one for before/after figures of one run);
    ``kernels`` False: the compiled kernels unimportable, as when pip found no compiler.
    Peak RSS is VmHWM of /proc/self/status: ru_maxrss survives exec on Linux and
    would report the benchmark's own (forked) high-water mark.  ``preload``: the command
    line's own imports (:data:`PRELOAD`) are done before the timing starts too.
    """
    code = (
        "import json,resource,time,sys\n"
        + ("" if kernels else NO_KERNELS)
        + "from cmsensord.cli import main\n"
        + (PRELOAD if preload else "")
        + "def cpu():\n"
        "    r = resource.getrusage(resource.RUSAGE_SELF); return r.ru_utime + r.ru_stime\n"
        "m0 = set(sys.modules)\n"
        "c0, t0 = cpu(), time.perf_counter()\n"
        f"rc = main(['replay', {str(capture)!r}, '--out', {str(out)!r}] + (['--akf-trace'] if {trace} else []))\n"
        "wall, c1 = time.perf_counter() - t0, cpu()\n"
        "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]\n"
        "print(json.dumps({'rc': rc, 'wall_s': wall, 'cpu_s': c1 - c0, 'peak_rss_mb': int(hwm) / 1024,\n"
        "                  'imports': len(set(sys.modules) - m0)}))\n"
    )
    env = dict(os.environ, PYTHONPATH=str(tree))
    # run in the tree: `python -c` puts the working directory before PYTHONPATH on sys.path
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tree)
    if p.returncode != 0:
        raise SystemExit(f"replay failed: {p.stderr}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    if r["rc"] != 0:
        raise SystemExit(f"replay failed: {p.stderr}")
    return r


def best_of(runs: list[dict]) -> dict:
    """Of repeated replays of one capture: the shortest wall and CPU times, the largest peak RSS
    (a shared machine only ever slows a run down)."""
    return {"wall_s": min(r["wall_s"] for r in runs), "cpu_s": min(r["cpu_s"] for r in runs),
            "peak_rss_mb": max(r["peak_rss_mb"] for r in runs), "imports": max(r.get("imports", 0) for r in runs)}


def trees(specs: list[str]) -> list[tuple[str, Path]]:
    """``--tree LABEL=DIR`` options -> [(label, checkout)], this checkout last (labelled
    "this" when there are others, else ""), each with its modules compiled to .pyc files
    (:func:`compiled`)."""
    out = [(lab, Path(d).resolve()) for lab, d in (t.split("=", 1) for t in specs)]
    out.append(("this" if out else "", ROOT))
    for _, tree in out:
        compiled(tree)
    return out


def compiled(tree: Path) -> None:
    """The .pyc files of checkout ``tree``'s packages written, as pip writes them on install:
    with PYTHONDONTWRITEBYTECODE=1 a checkout without them (a fresh worktree, or a module edited
    since) has every module compiled at each import, and the modules a replay or the daemon
    imports on first use (the order chain's) inside the timing: 0.02 CPU s of a 26-s RAW
    replay's 0.067 measured, which made an older tree's replay look 30 % dearer."""
    import compileall

    for pkg in ("cmsensord", "firmware_sim"):
        if (tree / pkg).is_dir():
            compileall.compile_dir(str(tree / pkg), quiet=1)


# ----------------------------------------------------------------- filterpy peer
def filterpy_bank(y: np.ndarray, R: np.ndarray, N: int, z_c: float) -> tuple[np.ndarray, np.ndarray]:
    """The same AKF (Kim et al. 2023 eqs. 3-15) with one filterpy KalmanFilter per filter.

    filterpy does the Kalman predict/update (eqs. 3-9); the adaptation of
    Q̂ (eqs. 10-14) and the outlier test (15) are done around it, per filter.
    """
    from filterpy.kalman import KalmanFilter

    T, C = y.shape
    n = R.shape[1]
    x_hat = np.empty((T, C, n))
    outl = np.zeros((T, C, n), dtype=np.uint8)
    for c in range(C):
        for i in range(n):
            kf = KalmanFilter(dim_x=1, dim_z=1)
            kf.F[:] = 1.0
            kf.H[:] = 1.0
            kf.R[:] = R[c, i]
            kf.x[:] = y[0, c]
            kf.P[:] = 1.0
            kf.Q[:] = 1e-3
            res2, dx2 = [], []
            for k in range(T):
                kf.predict()                                    # (3), (4)
                x_prior = float(kf.x[0, 0])
                kf.update(y[k, c])                              # (5)-(9)
                Y = float(kf.S[0, 0])
                K = float(kf.K[0, 0])
                x = float(kf.x[0, 0])
                dx = x - x_prior
                res2.append((y[k, c] - x) ** 2)
                dx2.append(dx * dx)
                if len(res2) > N:
                    res2.pop(0)
                    dx2.pop(0)
                M = sum(res2) / len(res2)                      # (11)
                G_hat = sum(dx2) / len(dx2)                    # (14)
                S = max(1.0, G_hat / (K * K * Y))              # (12), (13)
                kf.Q[:] = S * M                                # (10)
                x_hat[k, c, i] = x
                outl[k, c, i] = abs((y[k, c] - x_prior) / np.sqrt(Y)) > z_c   # (15)
    return x_hat, outl


def bank_vs_filterpy(seconds: float, channels: int = 4) -> dict | None:
    from cmsensord.dsp.akf import AkfBank, bank_r
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=channels, duration_s=seconds, seed=2)
    _, y = Board(sc, BoardConfig(n_channels=channels)).observations(int(seconds * 100))
    y = y.astype(np.float64)
    R = np.stack([bank_r(4e-3, 0.13, 10)] * channels)
    res = {"observations": y.shape[0], "channels": channels}
    for backend in ("c", "numpy"):
        try:
            bank = AkfBank(R, window=10, z_c=2.8, backend=backend)
        except RuntimeError:
            continue
        reps = 20 if backend == "c" else 1
        t0 = time.perf_counter()
        for _ in range(reps):
            bank = AkfBank(R, window=10, z_c=2.8, backend=backend)
            out = bank.process(y)
        res[f"bank_{backend}_s"] = (time.perf_counter() - t0) / reps
        res["x_hat"] = out.x_hat
        if backend == "c":      # only the outlier flags, as a decision takes them
            t0 = time.perf_counter()
            for _ in range(reps):
                flags = AkfBank(R, window=10, z_c=2.8, backend=backend).outliers(y)[0]
            res["bank_c_flags_s"] = (time.perf_counter() - t0) / reps
            assert np.array_equal(flags, out.outlier)
    try:
        import filterpy  # noqa: F401
    except ImportError:
        res["filterpy_s"] = None
        return res
    t0 = time.perf_counter()
    fx, _ = filterpy_bank(y, R, 10, 2.8)
    res["filterpy_s"] = time.perf_counter() - t0
    res["max_abs_diff"] = float(np.max(np.abs(fx - res["x_hat"])))
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=1800.0, help="simulated seconds per capture")
    ap.add_argument("--peer-seconds", type=float, default=60.0, help="seconds of input for the filterpy comparison")
    ap.add_argument("--channels", type=int, action="append", help="only these channel counts (default 1, 4, 8)")
    ap.add_argument("--no-trace", action="store_true", help="only the default logging (no --akf-trace rows)")
    ap.add_argument("--no-peer", action="store_true", help="skip the filterpy comparison")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR",
                    help="also replay with the code of another checkout, interleaved (e.g. before=/tmp/before)")
    ap.add_argument("--repeat", type=int, default=1, help="replays of each capture per code (the best is shown)")
    ap.add_argument("--scenario", default="degrading", help="firmware_sim scenario of the captures")
    ap.add_argument("--preload", action="store_true",
                    help="load the command line's own imports before timing (all imports excluded)")
    args = ap.parse_args()
    from cmsensord.dsp.akf import have_kernel

    print(f"# RMS chain benchmark: {args.seconds:g} s simulated per capture, {args.scenario} scenario; "
          f"compiled AKF kernel: {'yes' if have_kernel() else 'NO (numpy fallback)'}")
    print("# timed: main(['replay', ...]) in a fresh interpreter, after `import cmsensord.cli`"
          + (" and the command modules (--preload)" if args.preload else "")
          + ": the interpreter's start and those imports not counted; the configuration, the sink's"
          " open and close, the summary and the first use of every code path counted (modules the"
          " replay imports while timed, compiled then without .pyc files, are counted under 'imports')")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for C in args.channels or (1, 4, 8):
            cap = tmp / f"rms{C}.bin"
            make_capture(cap, C, args.seconds, args.scenario)
            size = cap.stat().st_size
            for trace in (False,) if args.no_trace else (False, True):
                runs: dict[str, list[dict]] = {}
                for _ in range(args.repeat):          # interleaved: each code sees the same machine
                    for label, tree in trees(args.tree):
                        out = tmp / f"out{C}{int(trace)}{label}"
                        shutil.rmtree(out, ignore_errors=True)
                        runs.setdefault(label, []).append(replay_in_subprocess(cap, out, trace, tree,
                                                                                preload=args.preload))
                for label, _ in trees(args.tree):
                    out = tmp / f"out{C}{int(trace)}{label}"
                    r = best_of(runs[label])
                    rss = r["peak_rss_mb"]
                    mcap = sum(p.stat().st_size for p in out.glob("*.mcap"))
                    rows.append((C, "akf trace" if trace else "default", label, args.seconds / r["wall_s"],
                                 size / r["wall_s"] / 1e6, args.seconds / r["cpu_s"], rss, mcap / 1e6,
                                 r["imports"]))
    print()
    print("| channels | logging | code | real-time factor | decode MB/s | RT factor per CPU-s | peak RSS MB "
          "| MCAP MB | imports |")
    print("| ---: | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for C, mode, label, rtf, mbs, cpu, rss, mc, imp in rows:
        print(f"| {C} | {mode} | {label} | {rtf:,.0f}x | {mbs:.2f} | {cpu:,.0f}x | {rss:.0f} | {mc:.2f} | {imp} |")
    if args.no_peer:
        return 0

    peer = bank_vs_filterpy(args.peer_seconds)
    print()
    print(f"| AKF bank, 10 filters x {peer['channels']} channels, {peer['observations']} observations "
          f"| seconds | vs filterpy |")
    print("| --- | ---: | ---: |")
    fp = peer.get("filterpy_s")
    for key, label in (("bank_c_s", "cmsensord bank, C kernel"),
                       ("bank_c_flags_s", "cmsensord bank, C kernel, outlier flags only (AkfBank.outliers)"),
                       ("bank_numpy_s", "cmsensord bank, numpy loop"),
                       ("filterpy_s", "filterpy, one KalmanFilter per filter")):
        if peer.get(key) is None:
            if key == "filterpy_s":
                print("| filterpy (not installed: pip install filterpy) | - | - |")
            continue
        ratio = f"{fp / peer[key]:,.0f}x faster" if fp else "-"
        if key == "filterpy_s":
            ratio = "1x"
        print(f"| {label} | {peer[key]:.4f} | {ratio} |")
    if fp:
        print(f"\nsame estimates: max |x̂_bank - x̂_filterpy| = {peer['max_abs_diff']:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
