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
* with ``LIVE_PROBE_FLOOR=S`` (board seconds), the floor under any Processor: after its first S
  board seconds the Processor does no work (:func:`_floor`), and the loop, the reader, the
  capture and the sink's ticks run as before, waking for the blocks the real one would name,
  so the daemon's CPU is what it pays besides the Processor (nothing is computed or written
  after S: a measurement, not a mode);
* with ``LIVE_PROBE_PARTS=FILE``, where the daemon's CPU goes: the CPU time of the thread
  in each of its parts (:data:`PARTS`: the Processor's call, within it the sink's writes; the
  sink's tick; the loop's step around the call; the reader's step, within it the decoder),
  and each thread's run time, from ``LIVE_PROBE_WARMUP_S`` (default 6) after the start for
  ``LIVE_PROBE_WINDOW_S`` (default 20) seconds: one JSON line appended to FILE at exit,
  ``{"argv": ..., "window_s": ..., "parts": {name: [calls, CPU s]}, "threads": {name: run s}}``
  (two clock reads a call: ~1 us more a call measured; a window the daemon's stop cuts short
  ends when its loop does, and a run that stops within the warm-up, a replay, writes nothing);
  with ``LIVE_PROBE_PARTS_DETAIL=1`` also the Processor's own steps (:data:`DETAIL_PARTS`: the
  frames' scan, the RMS observations, the RAW blocks, the banks, the decisions, the indicators,
  the alarms, the order chain, the tacho);
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


def _floor(processor_cls, after_s: float) -> None:
    """``processor_cls`` with, once an instance has handled ``after_s`` board seconds, its
    ``handle`` keeping only the newest frame's t0, ``wake_t0`` naming the last block of the
    next output period after it (the next /orders block, else the next decision: the block the
    real one names in a steady stream), and ``check_wall`` doing nothing."""
    handle, wake = processor_cls.handle, processor_cls.wake_t0

    def floor_handle(self, frames):
        if getattr(self, "_floor_newest", None) is None:
            handle(self, frames)
            if self.board_seconds >= after_s and self.clock.slot0_t0 is not None:
                self._floor_newest = self.clock.slot0_t0 + (self.clock.next_slot - 1) * self.block_len
            return
        if frames:
            self._floor_newest = max(self._floor_newest, frames[-1].t0_unwrapped)

    def floor_wake(self):
        newest = getattr(self, "_floor_newest", None)
        if newest is None:
            return wake(self)
        L, s0 = self.block_len, self.clock.slot0_t0
        rate = self.cfg.orders.output_rate_hz if self.orders is not None else 1 / self.cfg.monitor.decision_period_s
        period = round(self.fs / rate)
        k = -(-(newest + 2 * L - s0) // period)         # the first period whose last block is to come
        return s0 + k * period - L

    processor_cls.handle = floor_handle
    processor_cls.wake_t0 = floor_wake
    processor_cls.check_wall = lambda self, max_drift_s: None


#: name -> (module, class or None, attribute) of the parts LIVE_PROBE_PARTS times
PARTS = {
    "loop: Processor.handle": ("cmsensord.monitor.processor", "Processor", "handle"),
    "loop: within it, sink writes": ("cmsensord.sinks.rotating", "RotatingSink", "write"),
    "loop: within it, sink batch writes": ("cmsensord.sinks.rotating", "RotatingSink", "write_many"),
    "loop: sink tick": ("cmsensord.sinks.rotating", "RotatingSink", "tick"),
    "loop: a batch's step (the call and what follows it)": ("cmsensord.service.live", None, "_process"),
    "reader: a step (read, capture, decode, queue, pause)": ("cmsensord.link", "SerialReader", "_step"),
    "reader: within it, the decoder": ("cmsensord.protocol", "Decoder", "feed"),
}
#: more parts within the Processor's call, timed too with ``LIVE_PROBE_PARTS_DETAIL=1`` (nested:
#: a part's time holds the parts it calls)
DETAIL_PARTS = {f"loop: within it, {cls}.{attr}": (module, cls, attr) for module, cls, attr in (
    ("cmsensord.monitor.processor", "Processor", "_scanned"),
    ("cmsensord.monitor.processor", "Processor", "_flush_rms"),
    ("cmsensord.monitor.indicators", "Indicators", "rms"),
    ("cmsensord.monitor.processor", "Processor", "_run"),
    ("cmsensord.monitor.severity", "SeverityChain", "observe"),
    ("cmsensord.monitor.processor", "Processor", "_release_decisions"),
    ("cmsensord.monitor.severity", "SeverityChain", "release"),
    ("cmsensord.monitor.severity", "SeverityChain", "decision"),
    ("cmsensord.monitor.indicators", "Indicators", "take"),
    ("cmsensord.monitor.alarms", "Alarms", "see"),
    ("cmsensord.monitor.processor", "Processor", "_diagnostics_message"),
    ("cmsensord.monitor.processor", "Processor", "_feed_tacho"),
    ("cmsensord.monitor.processor", "Processor", "_few"),
    ("cmsensord.monitor.processor", "Processor", "_flush_raw"),
    ("cmsensord.monitor.raw", "RawInput", "blocks"),
    ("cmsensord.monitor.indicators", "Indicators", "raw"),
    ("cmsensord.monitor.held", "Held", "hand_over"),
    ("cmsensord.monitor.orders", "OrderChain", "add_samples"),
    ("cmsensord.monitor.orders", "OrderChain", "release"),
    ("cmsensord.monitor.shaft", "Shaft", "feed"),
)}


def _time_parts(warmup: float, window: float) -> tuple[dict, threading.Event, threading.Thread]:
    """Each of :data:`PARTS` wrapped to add its thread's CPU time to the dict returned, over
    ``window`` seconds from ``warmup`` seconds from now, or until the live loop returns or the
    event returned is set (the thread returned then ends the window); with the threads' run
    times (schedstat).  Nothing is counted when the event is set within ``warmup`` (``window_s``
    stays 0)."""
    import importlib

    got: dict = {"window_s": 0.0, "parts": {}, "threads": {}}
    on, end = threading.Event(), threading.Event()

    def timed(name, f):
        def part(*a, **kw):
            if not on.is_set():
                return f(*a, **kw)
            t = time.thread_time()
            try:
                return f(*a, **kw)
            finally:
                acc = got["parts"].setdefault(name, [0, 0.0])
                acc[0] += 1
                acc[1] += time.thread_time() - t
        return part

    detail = DETAIL_PARTS if os.environ.get("LIVE_PROBE_PARTS_DETAIL") else {}
    for name, (module, cls, attr) in {**PARTS, **detail}.items():
        owner = importlib.import_module(module)
        owner = getattr(owner, cls) if cls else owner
        setattr(owner, attr, timed(name, getattr(owner, attr)))

    from bench_live import thread_ns  # this directory is first on sys.path

    def run_times() -> dict[str, float]:
        names = {t.native_id: t.name for t in threading.enumerate()}
        return {names.get(int(tid), f"tid{tid}"): ns / 1e9 for tid, ns in thread_ns(os.getpid()).items()}

    def window_of_parts() -> None:
        if end.wait(warmup):
            return
        before, t0 = run_times(), time.monotonic()
        on.set()
        end.wait(window)
        on.clear()
        after = run_times()
        got["window_s"] = round(time.monotonic() - t0, 3)
        got["threads"] = {k: round(v - before.get(k, 0.0), 6) for k, v in after.items() if k != "parts"}

    thread = threading.Thread(target=window_of_parts, name="parts", daemon=True)
    thread.start()
    from cmsensord.service import live
    loop = live._loop

    def loop_then_end(*a, **kw):                # the window ends with the loop, the reader alive
        try:
            return loop(*a, **kw)
        finally:
            end.set()
            thread.join()

    live._loop = loop_then_end
    return got, end, thread


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


def _install(state: dict) -> None:
    """The latency probes: frames put in the queue (arrivals, the newest frame), the board
    clock's first anchor, the Processors made, and the sink's /orders writes, noted in ``state``."""
    from cmsensord import frame_queue
    from cmsensord.monitor import clock, processor
    from cmsensord.service import live

    put = frame_queue.FrameQueue.put

    def probed_put(self, frames):
        if frames:
            state["arrivals"].append((time.time_ns(), frames[-1].t0_unwrapped))
            t0 = max(f.t0_unwrapped for f in frames)
            state["newest"] = t0 if state["newest"] is None else max(state["newest"], t0)
        return put(self, frames)

    anchor = clock.BlockClock.anchor

    def probed_anchor(self, t0, wall_ns, *newest):         # newest: the live reader's, where the tree has it
        if state["anchor"] is None:
            state["anchor"] = (t0, wall_ns)
        return anchor(self, t0, wall_ns, *newest)

    init = processor.Processor.__init__

    def probed_init(self, *a, **kw):
        init(self, *a, **kw)
        state["procs"].append(self)

    open_sink = live.open_sink

    def probed_open_sink(*a, **kw):
        return _probe_sink(open_sink(*a, **kw), state)

    frame_queue.FrameQueue.put = probed_put            # type: ignore[method-assign]
    clock.BlockClock.anchor = probed_anchor     # type: ignore[method-assign]
    processor.Processor.__init__ = probed_init  # type: ignore[method-assign]
    live.open_sink = probed_open_sink


def main() -> int:
    report_path, rest = sys.argv[1], sys.argv[2:]
    no_kernels = "--no-kernels" in rest[:rest.index("--")]
    args = rest[rest.index("--") + 1:]
    if no_kernels:
        for name in ("cmsensord.dsp._akfkernel", "cmsensord.dsp._trackerkernel", "cmsensord._wirekernel"):
            sys.modules[name] = None  # type: ignore[assignment]  # import raises ImportError
    from cmsensord import link
    from cmsensord.cli import main as cli_main
    from cmsensord.monitor import processor

    state: dict = {"arrivals": [], "anchor": None, "writes": [], "procs": [], "newest": None}
    _install(state)
    if os.environ.get("LIVE_PROBE_FLOOR"):
        _floor(processor.Processor, float(os.environ["LIVE_PROBE_FLOOR"]))
    samples: list = []
    threads_out, stop = os.environ.get("LIVE_PROBE_THREADS"), threading.Event()
    if threads_out:
        threading.Thread(target=_sample_threads, args=(samples, stop), name="probe", daemon=True).start()
    parts_out = os.environ.get("LIVE_PROBE_PARTS")
    parts = (_time_parts(float(os.environ.get("LIVE_PROBE_WARMUP_S", "6")),
                         float(os.environ.get("LIVE_PROBE_WINDOW_S", "20"))) if parts_out else None)
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
    if parts_out and parts is not None:
        got, end, thread = parts
        end.set()                                   # a window the stop cut short ends here
        thread.join()
        if got["window_s"]:
            with open(parts_out, "a") as f:
                f.write(json.dumps({"argv": args, **got}) + "\n")
    if gc_out and gc_state is not None:
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
