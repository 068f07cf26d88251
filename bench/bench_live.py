#!/usr/bin/env python3
"""The live daemon's cost at 1x real time, beside a replay of the same capture.

Per configuration (RMS 4 channels; RAW 1 channel + tacho + the default 4 orders;
RAW 4 channels + tacho + 4 orders), with and without the compiled kernels: starts
the simulated board on a pty at 1x (``python -m firmware_sim --pty --speed 1``) and
the daemon on it (``cmsensord --config ... --capture cap.bin``, through
bench/live_probe.py), lets it warm up, then measures the daemon process alone over a
fixed window: CPU % of one core from its threads' run times (user and kernel, to the
nanosecond: /proc/<pid>/task/*/schedstat; the 10-ms clock ticks of /proc/<pid>/stat where
the kernel keeps no schedstat), and of it the main thread's (the loop and the Processor; the
rest is the serial reader's thread), RSS and peak RSS (VmRSS, VmHWM), and the order
latency (write time minus the sample's arrival, median and 95th percentile).  Then replays
the capture the daemon wrote (``cmsensord replay`` in a fresh process, imports excluded)
and gives its CPU per board second and the ratio live / replay.  The last column is the simulated
board's own CPU over the same window: what the daemon shares the machine with.

    python bench/bench_live.py [--seconds 60] [--warmup 8] [--only raw1] [--repeat 3] [--tree before=DIR]
                               [--idle-poll] [--floor 4]

``--repeat N`` runs every configuration N times, in rounds (each round runs them all in
turn), prints every run's row, then per configuration the least, median and most of its live
CPU % and live / replay: runs of one tree minutes apart scatter by tens of percent on a shared
machine, more than most changes move them.

``--idle-poll`` also runs every configuration with the CPUs polling when idle instead of
halting (bench/cpu_idle.py: ``/dev/cpu_dma_latency`` held at 0 over the live run and its replay;
root only), rows marked "(idle: poll)", right after the same configuration without: a diagnostic
of how much of the live cost over a replay's is the CPUs' halt between wake-ups, not a setting for
the board.

``--floor S`` also runs every configuration with the Processor idle after its first S board
seconds (bench/live_probe.py's ``LIVE_PROBE_FLOOR``: the loop, the reader, the capture and the
sink's ticks go on, waking for the blocks the Processor would name), rows marked "(floor)",
beside a replay of its own capture (the replay does all the work): the daemon's cost besides the
Processor's, the least any Processor, compiled or not, could be added to.  No order latency
(it writes no /orders after S).

``--tree LABEL=DIR`` (repeatable) runs the simulator, the daemon and the replay from
another checkout too (its C kernels built in place: ``python setup.py build_ext
--inplace``), interleaved with this one, for before/after figures of one run.

The machine is shared and noisy: compare rows of one run.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROBE = str(ROOT / "bench" / "live_probe.py")
sys.path.insert(0, str(ROOT / "bench"))

from bench_rms import trees as checkouts  # noqa: E402  (each compiled to .pyc, as installed)
from cpu_idle import idle_driver, polling_idle  # noqa: E402

TICK = os.sysconf("SC_CLK_TCK")

#: name -> (simulator arguments, label)
CONFIGS = {
    "rms4": (["--scenario", "faulty", "--mode", "rms", "--channels", "4"], "RMS 4 ch"),
    "raw1": (["--scenario", "faulty", "--mode", "raw", "--tacho", "--channels", "1"],
             "RAW 1 ch + tacho + 4 orders"),
    "raw4": (["--scenario", "faulty", "--mode", "raw", "--tacho", "--channels", "4"],
             "RAW 4 ch + tacho + 4 orders"),
    "raw1ll": (["--scenario", "faulty", "--mode", "raw", "--tacho", "--channels", "1"],
               "RAW 1 ch + tacho + 4 orders, low latency (orders.output_rate_hz: 50)"),
}
#: name -> more daemon configuration (YAML)
MORE_CONFIG = {"raw1ll": "orders:\n  output_rate_hz: 50\n"}


def cpu_s(pid: int) -> float:
    """utime + stime of the process (all its threads), seconds, in clock ticks (10 ms)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def thread_ns(pid: int) -> dict[str, int]:
    """Run time of each thread of the process, ns (the scheduler's ``sum_exec_runtime`` in
    /proc/<pid>/task/<tid>/schedstat: user and kernel time to the nanosecond); empty where the
    kernel keeps no schedstat."""
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            out[task.name] = int((task / "schedstat").read_text().split()[0])
        except (OSError, IndexError, ValueError):
            continue
    return out


class CpuWindow:
    """The CPU seconds a process uses from :meth:`start` to :meth:`stop`: its threads' run times
    (:func:`thread_ns`; a thread that ends inside the window is missed, the daemon's do not),
    else the clock ticks of /proc/<pid>/stat, whose 10-ms steps are a third of a 20-s window's
    0.15 % of a core."""

    main: float | None = None           #: after stop: the main thread's CPU seconds (None: ticks)

    def __init__(self, pid: int):
        self.pid = pid

    def start(self) -> None:
        self.ns0, self.ticks0 = thread_ns(self.pid), cpu_s(self.pid)

    def stop(self) -> float:
        ns1, ticks1 = thread_ns(self.pid), cpu_s(self.pid)
        if not ns1:
            self.main = None
            return ticks1 - self.ticks0
        main = str(self.pid)
        self.main = (ns1.get(main, 0) - self.ns0.get(main, 0)) / 1e9   # the main thread's share
        return sum(v - self.ns0.get(tid, 0) for tid, v in ns1.items()) / 1e9


def memory_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of the process, MB."""
    got = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key = line.split(":")[0]
            if key in ("VmRSS", "VmHWM"):
                got[key] = int(line.split()[1]) / 1024
    return got["VmRSS"], got["VmHWM"]


def tree_env(tree: Path) -> dict[str, str]:
    """The environment that runs the code of checkout ``tree``."""
    return dict(os.environ, PYTHONPATH=str(tree) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def live(tmp: Path, sim_args: list[str], kernels: bool, warmup: float, seconds: float,
         tree: Path, more: str = "", floor: float | None = None) -> dict:
    """The daemon at 1x on a simulated board, both of checkout ``tree``: CPU over the window,
    memory, latency, capture (``floor``: the Processor idle after that many board seconds)."""
    env = tree_env(tree)
    # the board in the tree: `python -m` puts the working directory before PYTHONPATH on sys.path
    sim = subprocess.Popen([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--speed", "1",
                            "--seed", "1", *sim_args], stdout=subprocess.PIPE, text=True, env=env, cwd=tree)
    assert sim.stdout is not None
    port = sim.stdout.readline().strip()
    cfg = tmp / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {tmp / 'logs'}\n  status_line: false\n{more}")
    report = tmp / "live.json"
    cap = tmp / "cap.bin"
    daemon = subprocess.Popen([sys.executable, PROBE, str(report), *([] if kernels else ["--no-kernels"]),
                               "--", "--config", str(cfg), "--capture", str(cap)], stderr=subprocess.PIPE,
                              text=True, env=env if floor is None else dict(env, LIVE_PROBE_FLOOR=str(floor)))
    try:
        time.sleep(warmup)
        used, board = CpuWindow(daemon.pid), CpuWindow(sim.pid)
        used.start()
        board.start()
        t0 = time.monotonic()
        time.sleep(seconds)
        c, b, t1 = used.stop(), board.stop(), time.monotonic()
        rss, hwm = memory_mb(daemon.pid)
    finally:
        daemon.send_signal(signal.SIGTERM)
        _, err = daemon.communicate(timeout=30)
        sim.terminate()
        sim.wait(timeout=5)
    if daemon.returncode != 0:
        raise SystemExit(f"daemon failed ({daemon.returncode}): {err}")
    r = json.loads(report.read_text())
    if floor is not None:                   # no /orders after the floor begins
        r["latency_ms"] = r["board_latency_ms"] = []
    lat = r["latency_ms"][int(len(r["latency_ms"]) * warmup / (warmup + seconds)):]
    blat = r["board_latency_ms"][int(len(r["board_latency_ms"]) * warmup / (warmup + seconds)):]
    return {"cpu_pct": 100 * c / (t1 - t0), "board_pct": 100 * b / (t1 - t0),
            "main_pct": None if used.main is None else 100 * used.main / (t1 - t0),
            "rss_mb": rss, "hwm_mb": hwm, "scipy": r["scipy"],
            "lat_med": statistics.median(lat) if lat else None,
            "lat_p95": sorted(lat)[int(0.95 * (len(lat) - 1))] if lat else None,
            "board_med": statistics.median(blat) if blat else None, "capture": cap}


def replay(tmp: Path, cap: Path, kernels: bool, env: dict[str, str]) -> dict:
    """``cmsensord replay`` of the capture in a fresh process: CPU of the replay, board seconds.
    The live daemon's probes (``LIVE_PROBE_*`` in the environment) are not the replay's."""
    report = tmp / "replay.json"
    env = {k: v for k, v in env.items() if not k.startswith("LIVE_PROBE_")}
    p = subprocess.run([sys.executable, PROBE, str(report), *([] if kernels else ["--no-kernels"]),
                        "--", "replay", str(cap), "--out", str(tmp / "replay")],
                       capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise SystemExit(f"replay failed: {p.stderr}")
    return json.loads(report.read_text())


def measure(name: str, kernels: bool, tree: Path, warmup: float, seconds: float,
            floor: float | None = None) -> tuple[dict, dict, float]:
    """One run of configuration ``name``: (live, replay, the replay's CPU % of a core); ``floor``:
    live with the Processor idle after that many board seconds (:func:`live`)."""
    with tempfile.TemporaryDirectory(prefix="bench_live") as tmp:
        lv = live(Path(tmp), CONFIGS[name][0], kernels, warmup, seconds, tree, MORE_CONFIG.get(name, ""), floor)
        rp = replay(Path(tmp), lv["capture"], kernels, tree_env(tree))
    return lv, rp, 100 * rp["cpu_s"] / rp["board_s"]


def print_spread(rows: list, repeat: int) -> None:
    """Per configuration and kernels: least / median / most of the live CPU % and of live / replay."""
    runs: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for label, k, lv, _rp, rep_pct in rows:
        runs.setdefault((label, k), []).append((lv["cpu_pct"], lv["cpu_pct"] / rep_pct))
    print(f"\n# the spread of {repeat} runs: least / median / most\n")
    print("| configuration | kernels | live CPU % | live / replay |")
    print("| --- | --- | ---: | ---: |")
    for (label, k), got in runs.items():
        cols = [sorted(v) for v in zip(*got)]
        print(f"| {label} | {k} | " + " | ".join(
            f"{c[0]:.3g} / {statistics.median(c):.3g} / {c[-1]:.3g}" for c in cols) + " |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="measuring window per configuration (s)")
    ap.add_argument("--warmup", type=float, default=8.0, help="seconds before the window (start-up)")
    ap.add_argument("--only", action="append", choices=sorted(CONFIGS), help="run only these configurations")
    ap.add_argument("--kernels", choices=("both", "on", "off"), default="both")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR",
                    help="also run the code of another checkout (e.g. before=/tmp/before)")
    ap.add_argument("--repeat", type=int, default=1, help="rounds of every configuration")
    ap.add_argument("--idle-poll", action="store_true",
                    help="also every configuration with the CPUs polling when idle (root; cpu_idle.py)")
    ap.add_argument("--floor", type=float, metavar="S",
                    help="also every configuration with the Processor idle after S board seconds")
    args = ap.parse_args()
    if args.floor is not None and args.floor >= args.warmup:
        ap.error("--floor must be less than --warmup (board seconds before the window)")
    modes: list[tuple[str, bool, float | None]] = [("", False, None)]
    modes += [("idle: poll", True, None)] if args.idle_poll else []
    modes += [("floor", False, args.floor)] if args.floor is not None else []
    kernel_runs = {"both": (True, False), "on": (True,), "off": (False,)}[args.kernels]
    trees = checkouts(args.tree)
    rows = []
    for _ in range(max(1, args.repeat)):
        for name in args.only or list(CONFIGS):
            label = CONFIGS[name][1]
            for kernels in kernel_runs:
                for (tree_label, tree), (mode_label, poll, floor) in itertools.product(trees, modes):
                    marks = ", ".join(m for m in (tree_label, mode_label) if m)
                    row_label = f"{label} ({marks})" if marks else label
                    with polling_idle(poll):
                        got = measure(name, kernels, tree, args.warmup, args.seconds, floor)
                    rows.append((row_label, "yes" if kernels else "no", *got))
                    print(f"  done: {row_label}, kernels {'on' if kernels else 'off'}", file=sys.stderr)
    print(f"# live daemon at 1x, {args.seconds:g} s window after {args.warmup:g} s warm-up; "
          f"replay of the same capture; cpuidle: {idle_driver()}\n")
    print("| configuration | kernels | live CPU % | of which the main thread | RSS MB | peak RSS MB "
          "| order latency ms (median / p95; "
          "board time, median) "
          "| scipy loaded | replay CPU s / board s | replay % | x real time | live / replay | board CPU % |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |")
    for label, k, lv, rp, rep_pct in rows:
        lat = (f"{lv['lat_med']:.0f} / {lv['lat_p95']:.0f}; {lv['board_med']:.0f}"
               if lv["lat_med"] is not None else "-")
        main = "-" if lv["main_pct"] is None else f"{lv['main_pct']:.3f}"
        print(f"| {label} | {k} | {lv['cpu_pct']:.3f} | {main} | {lv['rss_mb']:.0f} | {lv['hwm_mb']:.0f} | {lat} "
              f"| {'yes' if lv['scipy'] else 'no'} | {rp['cpu_s']:.3f} / {rp['board_s']:.0f} | {rep_pct:.3f} "
              f"| {rp['board_s'] / rp['cpu_s']:,.0f}x | {lv['cpu_pct'] / rep_pct:.1f} | {lv['board_pct']:.1f} |")
    if args.repeat > 1:
        print_spread(rows, args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
