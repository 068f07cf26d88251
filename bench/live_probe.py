#!/usr/bin/env python3
"""Run ``cmsensord ARGS`` in this process with probes, for bench/bench_live.py.

    python bench/live_probe.py REPORT.json [--no-kernels] -- ARGS...

``--no-kernels`` makes the compiled kernels unimportable (``sys.modules[name] =
None``), as on a board without a C compiler: the numpy fallbacks run.  The probes
change nothing the daemon computes:

* order latency: for every ``/cm/<ch>/orders`` message, the wall clock at its write
  minus the time the frame holding the block's first sample arrived; and in board
  time (``board_latency_ms``): the end of the newest frame in at its write minus the
  start of the frame holding the block's first sample.  Stamps are the board clock anchored
  to the wall clock when the Processor first sees a frame (possibly bytes the pty held
  since before the daemon opened it); the probe notes when the reader thread received
  each frame and takes the board clock's earliest arrival (the least arrival time minus
  the frame's board time) as the time a board sample arrives, so a loop that waits
  before processing shows its wait in the latency;
* the CPU seconds of ``main`` alone (imports excluded) and the board seconds processed;
* whether scipy was imported, and the peak RSS (VmHWM);
* with ``LIVE_PROBE_THREADS=FILE`` in the environment, the wake-ups of the daemon's threads:
  every ``SAMPLE_S`` the voluntary context switches (each a wait the thread went into) and
  CPU ticks of each thread by its Python name (/proc/self/task/<tid>/status and stat); at
  exit one JSON line is appended to FILE: ``{"path": cmsensord's directory, "argv": ...,
  "window_s": ..., "threads": {name: [wake-ups a second, CPU % of one core]}}`` over the
  last ``LIVE_PROBE_WINDOW_S`` (default 20) seconds sampled before the daemon was stopped
  (bench/bench_live.py stops it at the end of its window);
* with ``LIVE_PROBE_GC=FILE``, Python's cyclic garbage collector: at exit one JSON line is
  appended to FILE, ``{"argv": ..., "collections": {generation: count}, "cpu_s": {generation:
  CPU seconds of the collecting thread}, "tracked": objects tracked at exit}`` over ``main``
  (the collections a run makes, and what they cost it).

At exit the figures go to REPORT.json.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import threading
import time

#: seconds between two samples of the threads' wake-ups (LIVE_PROBE_THREADS)
SAMPLE_S = 1.0


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _probe_sink(sink, state: dict):
    """``sink`` with its writes of ``/orders`` messages noted in ``state["writes"]``:
    (wall ns at the write, stamp, the newest frame's end)."""
    write = sink.write

    def probed_write(topic, schema, stamp_ns, msg):
        if topic.endswith("/orders"):
            state["writes"].append((time.time_ns(), stamp_ns, state["newest"]))
        return write(topic, schema, stamp_ns, msg)

    sink.write = probed_write
    write_many = getattr(sink, "write_many", None)
    if write_many is not None:              # a decision's or a block's messages in one call

        def probed_write_many(messages):
            now = time.time_ns()
            state["writes"].extend((now, stamp_ns, state["newest"])
                                   for topic, _schema, stamp_ns, _msg in messages
                                   if topic.endswith("/orders"))
            return write_many(messages)

        sink.write_many = probed_write_many
    return sink


def _watch_gc() -> dict:
    """Collections by generation and the collecting thread's CPU seconds in them, counted from
    now into the dict returned (``gc.callbacks``)."""
    import gc

    state: dict = {"collections": {}, "cpu_s": {}, "start": 0.0}

    def noted(phase: str, info: dict) -> None:
        if phase == "start":
            state["start"] = time.thread_time()
            return
        g = info["generation"]
        state["collections"][g] = state["collections"].get(g, 0) + 1
        state["cpu_s"][g] = state["cpu_s"].get(g, 0.0) + time.thread_time() - state["start"]

    gc.callbacks.append(noted)
    return state


def _thread_counts() -> dict[str, list[int]]:
    """{thread name: [voluntary context switches, utime + stime ticks]} of this process."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/status") as f:
                vol = next(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt_switches"))
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except (OSError, StopIteration):
            continue                                # the thread ended meanwhile
        out[names.get(int(tid), f"tid{tid}")] = [vol, int(fields[11]) + int(fields[12])]
    return out


def _sample_threads(samples: list, stop: threading.Event) -> None:
    while not stop.wait(SAMPLE_S):
        samples.append([time.monotonic(), _thread_counts()])


def _thread_rates(samples: list, window: float) -> dict:
    """Wake-ups a second and CPU % of each thread over the last ``window`` seconds sampled."""
    if len(samples) < 2:
        return {"window_s": 0.0, "threads": {}}
    tb, b = samples[-1]
    ta, a = min(samples[:-1], key=lambda s: abs(tb - s[0] - window))
    tick = os.sysconf("SC_CLK_TCK")
    return {"window_s": tb - ta, "threads": {
        name: [round((b[name][0] - a[name][0]) / (tb - ta), 1),
               round(100 * (b[name][1] - a[name][1]) / tick / (tb - ta), 2)]
        for name in sorted(set(a) & set(b)) if name != "probe"}}


def main() -> int:
    report_path, rest = sys.argv[1], sys.argv[2:]
    no_kernels = "--no-kernels" in rest[:rest.index("--")]
    args = rest[rest.index("--") + 1:]
    if no_kernels:
        for name in ("cmsensord.dsp._akfkernel", "cmsensord.dsp._trackerkernel", "cmsensord._wirekernel"):
            sys.modules[name] = None  # type: ignore[assignment]  # import raises ImportError
    from cmsensord import link, service
    from cmsensord.cli import main as cli_main
    from cmsensord.monitor import clock, processor
    from cmsensord.service import live

    state: dict = {"arrivals": [], "anchor": None, "writes": [], "procs": [], "newest": None}

    put = link.FrameQueue.put

    def probed_put(self, frames):
        if frames:
            state["arrivals"].append((time.time_ns(), frames[-1].t0_unwrapped))
            t0 = max(f.t0_unwrapped for f in frames)
            state["newest"] = t0 if state["newest"] is None else max(state["newest"], t0)
        return put(self, frames)

    anchor = clock.BlockClock.anchor

    def probed_anchor(self, t0, wall_ns):
        if state["anchor"] is None:
            state["anchor"] = (t0, wall_ns)
        return anchor(self, t0, wall_ns)

    init = processor.Processor.__init__

    def probed_init(self, *a, **kw):
        init(self, *a, **kw)
        state["procs"].append(self)

    open_sink = live.open_sink

    def probed_open_sink(*a, **kw):
        return _probe_sink(open_sink(*a, **kw), state)

    link.FrameQueue.put = probed_put            # type: ignore[method-assign]
    clock.BlockClock.anchor = probed_anchor     # type: ignore[method-assign]
    processor.Processor.__init__ = probed_init  # type: ignore[method-assign]
    live.open_sink = probed_open_sink           # type: ignore[attr-defined]
    del service
    threads_out, samples, stop = os.environ.get("LIVE_PROBE_THREADS"), [], threading.Event()
    if threads_out:
        threading.Thread(target=_sample_threads, args=(samples, stop), name="probe", daemon=True).start()
    gc_out = os.environ.get("LIVE_PROBE_GC")
    gc_state = _watch_gc() if gc_out else None     # None: not watched
    c0 = _cpu()
    rc = cli_main(args)
    cpu = _cpu() - c0
    if threads_out:
        stop.set()
        window = float(os.environ.get("LIVE_PROBE_WINDOW_S", "20"))
        with open(threads_out, "a") as f:
            f.write(json.dumps({"path": os.path.dirname(link.__file__), "argv": args,
                                **_thread_rates(samples, window)}) + "\n")
    if gc_state is not None:
        import gc

        with open(gc_out, "a") as f:
            f.write(json.dumps({"argv": args, "collections": gc_state["collections"],
                                "cpu_s": {g: round(t, 6) for g, t in gc_state["cpu_s"].items()},
                                "tracked": len(gc.get_objects())}) + "\n")
    hwm = next(line for line in open("/proc/self/status") if line.startswith("VmHWM")).split()[1]
    procs = state["procs"]
    latency, board_latency = [], []
    if state["anchor"] is not None and state["arrivals"] and procs:
        fs, bl, rate = procs[-1].fs, procs[-1].block_len, procs[-1].cfg.orders.output_rate_hz
        t0_first, anchor_ns = state["anchor"]
        # wall time at which the frame of board sample t0_first arrived, at the earliest
        first_ns = min(a - (t0 - t0_first) * 1e9 / fs for a, t0 in state["arrivals"])
        for w, s, newest in state["writes"]:
            # a block's stamp is its last sample; its first sample waits longest
            first = round((s - anchor_ns) * fs / 1e9 - fs / rate + 1)
            latency.append((w - first_ns - (first // bl) * bl * 1e9 / fs) / 1e6)
            # in board time: the newest sample in when written, minus the block's first
            # (the frame holding it): free of this machine's speed
            if newest is not None:
                board_latency.append((newest - t0_first + bl - (first // bl) * bl) * 1e3 / fs)
    with open(report_path, "w") as f:
        json.dump({"rc": rc, "cpu_s": cpu, "board_s": procs[-1].board_seconds if procs else 0.0,
                   "latency_ms": latency, "board_latency_ms": board_latency, "scipy": "scipy" in sys.modules,
                   "peak_rss_mb": int(hwm) / 1024}, f)
    return rc


if __name__ == "__main__":
    sys.exit(main())
