#!/usr/bin/env python3
"""What a wake-up costs: the Processor alone, back to back against paced at 1x.

Builds a capture with firmware_sim (RAW 1 channel + tacho of the `faulty` motor, and
RMS 4 channels), then, per capture and part length, hands a fresh Processor the
capture in parts of that much board time twice: back to back (as a replay does) and
paced at 1x (a sleep until the next part is due after each, as the live loop waits
for the board), and prints the CPU per board second of each and their ratio.  The
first 6 s go in one call (start-up excluded); the sink keeps the messages in memory
(no MCAP, no serial port, no reader thread).  The same calls on the same frames: the
ratio is what doing the work in wake-ups costs over doing it back to back, the part of
the live daemon's cost over a replay's (bench/bench_live.py) that no change to the
reader or the loop removes.

    python bench/bench_wake.py [--seconds 20] [--span 0.1 --span 1.0] [--repeat 2] [--orders-only] [--idle]
                               [--footprint] [--idle-poll]

``--orders-only`` also measures, paced, the order path alone (:func:`orders_only`: the
RAW blocks, the tacho, the order tracker and its /orders messages; no observation, bank,
indicator or decision).  Not what the daemon does: the least a wake-up carrying the
/orders block costs, against the whole chain's back to back.

``--idle`` also measures an empty loop paced the same way (:func:`idle`: a sleep until the
next part is due, no work): what a wake-up alone costs this interpreter on this machine, the
part of any paced loop's cost no change to the work removes.

``--footprint`` also times (wall, median of the calls) synthetic workloads of the same
Python and numpy calls, back to back and each after a sleep of the part's length
(:func:`footprint_work`): 300 distinct small functions called once each (a broad code
footprint, as the chain's ~330 calls a wake-up run each once) and the first of them called
300 times (a narrow one); and compiled work of a known memory footprint (:func:`gather_work`:
one numpy call reading a cache line in each of 1, 256 and 4,096 pages): what one compiled
call costs after a sleep, and how much more the memory it reads adds.  Nothing of cmsensord
runs: what a wake-up's work costs over the same work back to back on this machine, by how much
distinct code and memory it touches.

``--idle-poll`` also measures everything with the CPUs polling when idle instead of halting
(bench/cpu_idle.py: ``/dev/cpu_dma_latency`` held at 0, root only), marked "(idle: poll)": the
Processor's runs interleaved with the others in each repeat, the ``--idle`` and ``--footprint``
tables once more after theirs.  How much of the cold factor is the CPU's halt between wake-ups
(on a virtual machine, the host's work on the core meanwhile); a diagnostic, not a setting for
the board.

``--repeat N`` measures each N times (back to back and paced in turn) and shows the
least CPU of each.  Figures are ratios measured side by side in one run.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bench_raw
import bench_rms
from cmsensord.config import default_config
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import Frame, iter_frames
from cmsensord.sinks.memory import ListSink
from cpu_idle import idle_driver, polling_idle

#: name -> (label, how its capture of the `faulty` motor is made: path, seconds)
CAPTURES = {"raw1": ("RAW 1 ch + tacho + 4 orders", lambda p, s: bench_raw.make_capture(p, "faulty", 1, s)),
            "rms4": ("RMS 4 ch", lambda p, s: bench_rms.make_capture(p, 4, s, scenario="faulty"))}
#: board seconds handed over in one call before the measured parts (start-up)
WARMUP_S = 6.0


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def parts_of(frames: list[Frame], span: int) -> list[list[Frame]]:
    """``frames`` cut where a frame's t0 is ``span`` board samples past its part's first."""
    out, start = [], 0
    for k in range(1, len(frames)):
        if frames[k].t0_unwrapped - frames[start].t0_unwrapped >= span:
            out.append(frames[start:k])
            start = k
    out.append(frames[start:])
    return out


def orders_only(proc: Processor) -> None:
    """``proc`` made to run the order path alone: no observation, bank, indicator or decision
    (what the start-up left held for the banks is dropped)."""
    def nothing(*_args, **_kw):
        return []
    proc.held.take_rows()
    proc.held.take_blocks()
    proc._observe = nothing                     # type: ignore[method-assign]
    proc._release_decisions = nothing           # type: ignore[method-assign]
    proc.indicators.raw = nothing               # type: ignore[method-assign]
    proc.indicators.release = nothing           # type: ignore[method-assign]


def measure(frames: list[Frame], span_s: float, seconds: float, paced: bool,
            only_orders: bool = False) -> tuple[float, float]:
    """CPU seconds per board second of a fresh Processor's calls on parts of ``span_s``, and
    the median wall seconds of one call (``only_orders``: :func:`orders_only`, after the start-up)."""
    sink = ListSink()
    proc = Processor(default_config(), sink, clock_ns=lambda: 10**18)
    proc.handle(frames[:50])                # the STATUS frame: the board's rate
    fs, first = proc.fs, frames[0].t0_unwrapped
    i = next(k for k, f in enumerate(frames) if f.t0_unwrapped - first > WARMUP_S * fs)
    proc.handle(frames[50:i])
    if only_orders:
        orders_only(proc)
    parts = parts_of(frames[i:], max(1, round(span_s * fs)))[:max(1, round(seconds / span_s))]
    sink.messages.clear()
    c0, t0, walls = cpu_s(), time.monotonic(), []
    for k, part in enumerate(parts):
        w = time.perf_counter()
        proc.handle(part)
        walls.append(time.perf_counter() - w)
        sink.messages.clear()
        if paced:
            wait = t0 + (k + 1) * span_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)
    used = cpu_s() - c0
    proc.finish()
    return used / (len(parts) * span_s), sorted(walls)[len(walls) // 2]


def measure_all(frames: list[Frame], span_s: float, seconds: float, alone: bool) -> dict[str, tuple[float, float]]:
    """:func:`measure` back to back, paced, and (``alone``) paced on the order path alone."""
    got = {"tight": measure(frames, span_s, seconds, paced=False),
           "paced": measure(frames, span_s, seconds, paced=True)}
    if alone:
        got["orders"] = measure(frames, span_s, seconds, paced=True, only_orders=True)
    return got


def idle(span_s: float, seconds: float) -> float:
    """CPU seconds per wake-up of a loop that sleeps until its next part of ``span_s`` is due,
    for ``seconds`` of wall time, and does nothing else."""
    n = max(1, round(seconds / span_s))
    c0, t0 = cpu_s(), time.monotonic()
    for k in range(n):
        wait = t0 + (k + 1) * span_s - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    return (cpu_s() - c0) / n


def print_idle(spans: list[float], seconds: float, repeat: int, title: str = "") -> None:
    """The table of :func:`idle` per span (least of ``repeat``)."""
    print(f"\n# an empty loop paced at 1x, {seconds:g} s per span (least of {repeat}){title}\n")
    print("| part s | wake-ups a second | CPU us per wake-up | % of a core |")
    print("| ---: | ---: | ---: | ---: |")
    for span in spans:
        per = min(idle(span, seconds) for _ in range(repeat))
        print(f"| {span:g} | {1 / span:g} | {1e6 * per:.0f} | {100 * per / span:.3f} |")


#: distinct functions of the broad synthetic workload (the chain's calls a wake-up, in round figures)
FOOTPRINT_CALLS = 300


def footprint_work(count: int = FOOTPRINT_CALLS) -> dict[str, Callable[[], float]]:
    """Two workloads of ``count`` calls of small functions alike (arithmetic, a dict, a list,
    a numpy element): ``broad`` calls ``count`` distinct ones once each, ``narrow`` the first
    of them ``count`` times."""
    funcs = []
    for i in range(count):
        src = (f"def f(x, a):\n    y = x * {i + 1} + {i}\n    if y % 3 == {i % 3}:\n        y -= {i}\n"
               f"    d = {{'k{i}': y, 'j': [y, {i}]}}\n    return d['k{i}'] + len(d['j']) + float(a[{i % 50}])\n")
        space: dict = {}
        exec(src, space)                    # distinct code objects: a broad footprint
        funcs.append(space["f"])
    a = np.arange(100.0)

    def broad() -> float:
        return sum(f(3, a) for f in funcs)

    def narrow() -> float:
        f = funcs[0]
        return sum(f(3, a) for _ in funcs)
    return {"broad": broad, "narrow": narrow, **gather_work()}


#: pages (4 KiB) the compiled workloads read one element of
GATHER_PAGES = (1, 256, 4096)


def gather_work(pages: tuple[int, ...] = GATHER_PAGES) -> dict[str, Callable[[], float]]:
    """Compiled work of a known memory footprint: one numpy gather and sum reading one float64
    in each of ``pages`` distinct 4-KiB pages (a different cache line of each), two Python calls
    whatever the count: what touching that much memory costs after a sleep, without the
    interpreter's own footprint growing with it."""
    per_page = 4096 // 8
    work: dict[str, Callable[[], float]] = {}
    for n in pages:
        buf = np.ones(n * per_page)
        idx = np.arange(n) * per_page + (np.arange(n) * 8) % per_page

        def gather(buf: np.ndarray = buf, idx: np.ndarray = idx) -> float:
            return float(buf[idx].sum())
        work[f"numpy gather, {n} page{'s' if n > 1 else ''}"] = gather
    return work


def work_wall(work: Callable[[], float], span_s: float, seconds: float, paced: bool) -> float:
    """Median wall seconds of one call of ``work``: called back to back, or each after a sleep
    of ``span_s``, for about ``seconds`` of wall time (at most 200 calls)."""
    walls = []
    for _ in range(max(20, min(200, round(seconds / span_s)))):
        if paced:
            time.sleep(span_s)
        t = time.perf_counter()
        work()
        walls.append(time.perf_counter() - t)
    return sorted(walls)[len(walls) // 2]


def print_footprint(spans: list[float], seconds: float, repeat: int, title: str = "") -> None:
    """The table of :func:`footprint_work`'s workloads per span (least of ``repeat``)."""
    print(f"\n# synthetic work: {FOOTPRINT_CALLS} small calls, or a numpy gather; wall us a call "
          f"(median; least of {repeat}){title}\n")
    print("| workload | part s | back to back | after a sleep of the part | after a sleep / back to back |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for name, work in footprint_work().items():
        for span in spans:
            tight = min(work_wall(work, span, seconds, paced=False) for _ in range(repeat))
            slept = min(work_wall(work, span, seconds, paced=True) for _ in range(repeat))
            print(f"| {name} | {span:g} | {1e6 * tight:.1f} | {1e6 * slept:.1f} | {slept / tight:.1f} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="board seconds measured per run")
    ap.add_argument("--span", type=float, action="append", help="board seconds a part (default 0.1 and 1.0)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", action="append", choices=sorted(CAPTURES))
    ap.add_argument("--orders-only", action="store_true",
                    help="also the order path alone, paced (RAW captures)")
    ap.add_argument("--idle", action="store_true", help="also an empty loop paced the same way")
    ap.add_argument("--footprint", action="store_true",
                    help="also synthetic work of many distinct or one repeated function, slept between")
    ap.add_argument("--idle-poll", action="store_true",
                    help="also everything with the CPUs polling when idle, not halting (root; cpu_idle.py)")
    args = ap.parse_args()
    spans = args.span or [0.1, 1.0]
    modes = [("", False)] + ([(" (idle: poll)", True)] if args.idle_poll else [])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.only or list(CAPTURES):
            label, make = CAPTURES[name]
            cap = Path(tmp) / f"{name}.bin"
            make(cap, WARMUP_S + args.seconds + 2)       # the RAW and RMS benchmarks' captures
            frames = iter_frames(cap.read_bytes())[0]
            alone = args.orders_only and name.startswith("raw")
            for span in spans:
                runs: dict[tuple[str, str], list[tuple[float, float]]] = {}
                for _ in range(args.repeat):
                    for idle_label, poll in modes:
                        with polling_idle(poll):
                            got = measure_all(frames, span, args.seconds, alone)
                        for kind, value in got.items():
                            runs.setdefault((idle_label, kind), []).append(value)
                for idle_label, _poll in modes:
                    rows.append((label + idle_label, span,
                                 {k: min(v) for (m, k), v in runs.items() if m == idle_label}))
                print(f"  done: {label}, parts of {span:g} s", file=sys.stderr, flush=True)
    print(f"# the Processor alone, {args.seconds:g} board s in parts, back to back and paced at 1x "
          f"(least of {args.repeat}); cpuidle: {idle_driver()}\n")
    extra = " | paced, the order path alone: CPU ms / board s | its / back to back" if args.orders_only else ""
    print("| capture | part s | back to back: CPU ms / board s | paced at 1x: CPU ms / board s "
          f"| paced at 1x: % of a core | paced / back to back | a call, wall us: back to back / paced{extra} |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |" + (" ---: | ---: |" if args.orders_only else ""))
    for label, span, got in rows:
        (tight, tight_wall), (paced, paced_wall) = got["tight"], got["paced"]
        line = (f"| {label} | {span:g} | {1000 * tight:.2f} | {1000 * paced:.2f} | {100 * paced:.3f} "
                f"| {paced / tight:.1f} | {1e6 * tight_wall:.0f} / {1e6 * paced_wall:.0f} |")
        if args.orders_only:
            alone = got["orders"][0] if "orders" in got else None
            line += f" {1000 * alone:.2f} | {alone / tight:.1f} |" if alone is not None else " - | - |"
        print(line)
    for idle_label, poll in modes:
        with polling_idle(poll):
            if args.idle:
                print_idle(spans, args.seconds, args.repeat, idle_label)
            if args.footprint:
                print_footprint(spans, args.seconds, args.repeat, idle_label)
    return 0


if __name__ == "__main__":
    sys.exit(main())
