"""The live loop batches frames by time: the same messages as one frame per call.

The serial source hands the Processor what the reader queued every ``BATCH_S``
seconds (or once ``BATCH_FRAMES`` wait), not each read's few frames; the
Processor's results do not depend on how the frames are cut into calls.  In
process: a reader thread on a paced fake port, batched as the daemon batches,
against one frame per call.  Through real processes: the daemon on a pty, whose
batches are whatever the timing gave, against a replay of its capture (one
frame per call).
"""

from __future__ import annotations

import threading
import time

from cmsensord.config import default_config
from cmsensord.frame_queue import FrameQueue
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import Frame, FrameType, iter_frames
from cmsensord.service.live import output_parts
from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.memory import ListSink
from cmsensord.source import BATCH_FRAMES, BATCH_S, HOLD_S, SerialSource
from messages import comparable
from processes import cmsensord, start_board, start_daemon, stop


def raw_capture(seconds: float, channels: int = 1) -> bytes:
    """RAW blocks + TACHO of the faulty motor (default orders 1x-4x are tracked)."""
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=channels, duration_s=seconds, seed=3)
    return Board(sc, BoardConfig(n_channels=channels, mode="raw", tacho=True)).generate(seconds)


def rms_capture(seconds: float, channels: int = 4) -> bytes:
    """RMS frames of the faulty motor, 100 a second."""
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=channels, duration_s=seconds, seed=3)
    return Board(sc, BoardConfig(n_channels=channels, mode="rms")).generate(seconds)


def one_frame_per_call(frames, cfg) -> ListSink:
    """The messages of a Processor handed ``frames`` one per call."""
    one = ListSink()
    proc = Processor(cfg, one, clock_ns=lambda: 10**18)
    for f in frames:
        proc.handle([f])
    proc.finish()
    return one


def by_topic(messages) -> dict[str, list]:
    """comparable() messages per topic, each in its own order; events as a sorted list (the
    tacho's events and the frames' interleave by call, each one's stamp is its own)."""
    out: dict[str, list] = {}
    for topic, stamp, msg in comparable(messages):
        if topic == "/cm/events" and msg["kind"] in ("link_lost", "link_restored", "link_stalled"):
            continue                                 # wall-clock events of a live link
        key = topic if "method" not in msg else f"{topic} {msg['method']}"
        out.setdefault(key, []).append((stamp, msg))
    if "/cm/events" in out:
        out["/cm/events"].sort(key=repr)
    return out


class PacedPort:
    """A fake serial port returning ``reads`` one per ``read`` call, ``pause`` s apart."""

    def __init__(self, reads: list[bytes], pause: float):
        self.reads, self.pause = list(reads), pause
        self.in_waiting = 0
        self.closed = False

    def read(self, n: int) -> bytes:
        time.sleep(self.pause)
        return self.reads.pop(0) if self.reads else b""

    def close(self) -> None:
        self.closed = True


def test_the_loops_batches_give_the_messages_of_one_frame_per_call():
    data = raw_capture(4.0)
    cfg = default_config(1)
    frames, _ = iter_frames(data)
    one = one_frame_per_call(frames, cfg)

    batched, sizes = ListSink(), []
    proc = Processor(cfg, batched, clock_ns=lambda: 10**18)
    port = PacedPort([data[k:k + 1100] for k in range(0, len(data), 1100)], pause=0.001)
    with SerialSource("/dev/fake", baud=921600, open_port=lambda: port) as src:
        for batch in src:
            sizes.append(len(batch))
            proc.handle(batch)
            if not port.reads and not batch:
                break
        src.stop()
        for batch in src:
            sizes.append(len(batch))
            proc.handle(batch)
    proc.finish()

    assert sum(sizes) == len(frames)
    assert max(sizes) > 20                          # really batched: many reads per call
    a, b = by_topic(one.messages), by_topic(batched.messages)
    assert len(a["/cm/ch0/orders recursive"]) >= 35 and len(a["/cm/ch0/severity"]) >= 3
    assert a == b


def test_raw_without_a_tacho_gives_its_indicator_alarms_the_same_stamps_however_it_is_called():
    """RAW blocks and no tacho (no orders, nothing held): a call of seconds (a replay's) wrote
    the decisions of its blocks before their indicator records, so an alarm the records raised
    was stamped at the newest event written (3 s late here), not at its record, unlike one
    frame per call (live). Each alarm event is stamped at the record that raised it."""
    import dataclasses

    from cmsensord.config.alarms import AlarmRuleConfig, AlarmsConfig
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=1, duration_s=12.0, seed=3)
    frames, _ = iter_frames(Board(sc, BoardConfig(n_channels=1, mode="raw", tacho=False)).generate(12.0))
    rule = AlarmRuleConfig(name="rms", indicator="accel_rms", alert=0.001)
    cfg = dataclasses.replace(default_config(1), alarms=AlarmsConfig(rules=(rule,)))
    whole = ListSink()
    proc = Processor(cfg, whole, clock_ns=lambda: 10**18)
    proc.handle(frames)
    proc.finish()
    records = [t for topic, t, _ in whole.messages if topic == "/cm/ch0/indicators"]
    alerts = [t for topic, t, m in whole.messages if topic == "/cm/events" and m["kind"] == "alarm_alert"]
    assert len(records) >= 10 and alerts == [records[0]]
    assert by_topic(whole.messages) == by_topic(one_frame_per_call(frames, cfg).messages)


def test_the_serial_source_wakes_every_batch_period_or_when_enough_frames_wait():
    """Frames trickling in come out together once per BATCH_S, not one call per read; a burst
    of BATCH_FRAMES comes out at once."""
    from cmsensord.protocol import encode_rms

    trickle = [encode_rms(i, i * 250, [1.0]) for i in range(40)]
    port = PacedPort(trickle, pause=0.005)          # one frame per 5 ms
    with SerialSource("/dev/fake", baud=921600, open_port=lambda: port) as src:
        got, t_first = [], None
        for batch in src:
            if batch:
                t_first = t_first or time.monotonic()
                got.append(len(batch))
            if sum(got) >= 40:
                break
        src.stop()
    assert len(got) <= 40 * 0.005 / BATCH_S + 2 and max(got) >= 5, got

    burst = b"".join(encode_rms(i, i * 250, [1.0]) for i in range(BATCH_FRAMES))
    port = PacedPort([burst], pause=0.0)
    with SerialSource("/dev/fake", baud=921600, open_port=lambda: port, timeout=5.0) as src:
        t = time.monotonic()
        first = next(b for b in src if b)
        waited = time.monotonic() - t
        src.stop()
    assert len(first) == BATCH_FRAMES and waited < 4.0


def test_live_raw_with_orders_on_a_pty_equals_the_replay_of_its_capture(tmp_path):
    """The daemon at 1x on a pty (batches of ~5 blocks, cut wherever the timing fell) writes
    the messages a replay of its capture writes (one read of 64 kB per call)."""
    a, b = _live_and_replay(tmp_path, ("--mode", "raw", "--tacho", "--duration", "5"), 1.0)
    assert len(a["/cm/ch0/orders recursive"]) >= 30
    assert a == b


def _live_and_replay(tmp_path, board: tuple[str, ...], settle_s: float, config: str = "") -> tuple[dict, dict]:
    """The faulty motor's board (``board``: more firmware_sim arguments) at 1x on a pty, the
    daemon on it with ``--capture`` stopped ``settle_s`` after the board has sent all, then a
    replay of the capture with the daemon's configuration: both runs' messages by topic."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "faulty", *board, "--speed", "1", "--seed", "2", "--link", str(link))
    d = start_daemon(tmp_path, link, "--capture", str(tmp_path / "cap.bin"), config=config)
    sim.stdout.readline()                            # the board's stats: all is sent
    time.sleep(settle_s)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    live = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    r = cmsensord("replay", str(tmp_path / "cap.bin"), "--config", str(tmp_path / "cmsensord.yaml"),
                  "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    return by_topic(live), by_topic(read_messages(next((tmp_path / "replay").glob("*.mcap"))))


def test_the_loop_wakes_with_the_frame_that_completes_an_orders_block():
    """Processor.wake_t0 names the block whose TACHO frame (the last of a block) completes the
    next /orders block: fed one frame per call, every /orders block after the first comes out
    in the call of exactly that frame, so a loop waking then adds no latency to the orders."""
    frames, _ = iter_frames(raw_capture(3.0))
    sink = ListSink()
    proc = Processor(default_config(1), sink, clock_ns=lambda: 10**18)
    wake, emitted_at = None, []
    for f in frames:
        before = len(sink.topic("/cm/ch0/orders"))
        proc.handle([f])
        if len(sink.topic("/cm/ch0/orders")) > before:
            emitted_at.append((f.type, f.t0_unwrapped, wake))
        wake = proc.wake_t0()
    assert len(emitted_at) >= 25
    assert all(t == FrameType.TACHO and t0 == w for t, t0, w in emitted_at[1:]), emitted_at[:5]


def test_a_queue_told_the_block_to_wake_at_returns_when_its_tacho_frame_is_in():
    q = FrameQueue(100)
    q.wake_at(500)
    threading.Timer(0.05, lambda: q.put([Frame(FrameType.RAW, 1, 500, 0, 0, b"")])).start()
    threading.Timer(0.1, lambda: q.put([Frame(FrameType.TACHO, 2, 500, 0, 0, b"\0\0")])).start()
    t = time.monotonic()
    got = q.get(timeout=5.0, enough=1000)
    assert [f.type for f in got] == [FrameType.RAW, FrameType.TACHO] and time.monotonic() - t < 4.0
    q.put([Frame(FrameType.TACHO, 3, 750, 0, 0, b"\0\0")])  # the wish was used: a get waits again
    t = time.monotonic()
    assert len(q.get(timeout=0.2, enough=1000)) == 1 and time.monotonic() - t >= 0.15


def test_rms_batches_take_one_call_per_decision_and_give_the_messages_of_one_frame_per_call():
    """The loop's way with RMS frames: frames wait in the queue for the block that
    completes the next decision, and a batch is handled in parts ending with such blocks: one
    Processor call per decision instead of one per 0.1 s, the messages (and their order in the
    file) those of one frame per call."""
    data = rms_capture(8.0)
    cfg = default_config(4)
    frames, _ = iter_frames(data)
    one = one_frame_per_call(frames, cfg)

    batched, parts = ListSink(), []
    proc = Processor(cfg, batched, clock_ns=lambda: 10**18)
    port = PacedPort([data[k:k + 280] for k in range(0, len(data), 280)], pause=0.002)   # 0.1 s each
    with SerialSource("/dev/fake", baud=921600, open_port=lambda: port) as src:
        for batch in src:
            for part in output_parts(batch, proc.wake_t0, round(BATCH_S * 25000), round(HOLD_S * 25000)):
                parts.append(part)
                proc.handle(part)
            src.queue.wake_at(proc.wake_t0())
            if not port.reads and not batch and not len(src.queue):
                break
        src.stop()
        for batch in src:
            parts.append(batch)
            proc.handle(batch)
    proc.finish()

    assert sum(len(p) for p in parts) == len(frames)
    decisions = len(one.topic("/cm/ch0/severity"))
    assert decisions >= 6
    # one part per decision, and one more for a batch's frames past it (this port runs at ~50x;
    # at 1x a batch ends with the block completing the decision): not one per 0.1 s (80)
    assert len([p for p in parts if p]) <= 2 * decisions + 3, [len(p) for p in parts]
    assert by_topic(one.messages) == by_topic(batched.messages)
    assert [(t, s) for t, s, _ in one.messages] == [(t, s) for t, s, _ in batched.messages]


def test_a_queue_keeps_its_frames_at_the_timeout_while_the_block_to_wake_at_is_to_come():
    q = FrameQueue(100)
    q.wake_at(500)
    q.put([Frame(FrameType.RMS, 1, 250, 0, 0, b"")])
    t = time.monotonic()
    assert q.get(timeout=0.05, enough=1000, hold_s=5.0) == [] and len(q) == 1 and time.monotonic() - t >= 0.04
    assert q.hint == 500
    q.wake_at(500)                                  # the loop names it again after its work
    threading.Timer(0.05, lambda: q.put([Frame(FrameType.RMS, 2, 750, 0, 0, b"")])).start()
    got = q.get(timeout=5.0, enough=1000, hold_s=5.0)            # a later block: that one is in
    assert [f.seq for f in got] == [1, 2]
    q.put([Frame(FrameType.RMS, 3, 1000, 0, 0, b"")])
    assert [f.seq for f in q.get(timeout=0.05, enough=1000, hold_s=5.0)] == [3]      # no block named: at the timeout
    q.wake_at(2000)
    q.put([Frame(FrameType.RMS, 4, 1250, 0, 0, b"")])
    time.sleep(0.06)
    assert [f.seq for f in q.get(timeout=0.01, enough=1000, hold_s=0.05)] == [4]     # waited hold_s: out


def test_a_queue_told_the_block_to_wake_at_returns_when_its_rms_frame_is_in():
    """An RMS block is one frame (without a tacho): it completes its block, so the decision it
    ends is handled when it comes, not with the next block's frame."""
    q = FrameQueue(100)
    q.wake_at(500)
    threading.Timer(0.05, lambda: q.put([Frame(FrameType.RMS, 1, 250, 0, 0, b"")])).start()
    threading.Timer(0.1, lambda: q.put([Frame(FrameType.RMS, 2, 500, 0, 0, b"")])).start()
    t = time.monotonic()
    got = q.get(timeout=5.0, enough=1000, hold_s=5.0)
    assert [f.seq for f in got] == [1, 2] and time.monotonic() - t < 4.0


def test_frames_the_loop_keeps_come_first_in_the_next_batch_and_wait_as_queued_ones():
    """SerialSource.keep: the frames past the block that completed a decision wait for the block
    completing the next, with the frames queued meanwhile; at a timeout while a block is named
    they stay (hold_s at most); with none named they come out."""
    def rms(seq: int, t0: int) -> Frame:
        return Frame(FrameType.RMS, seq, t0, 0, 0, b"")

    src = SerialSource("/dev/fake", baud=921600, timeout=0.05, hold_s=0.3)
    batches = iter(src)
    src.keep([rms(1, 250)])
    src.wake_at(1000, 25000.0)
    assert next(batches) == [] and src.waiting == 1                  # the timeout: kept
    threading.Timer(0.02, lambda: src.queue.put([rms(2, 500), rms(3, 1000)])).start()
    assert [f.seq for f in next(batches)] == [1, 2, 3] and src.waiting == 0
    src.keep([rms(4, 1250)])
    src.wake_at(None, 25000.0)
    assert [f.seq for f in next(batches)] == [4]                      # none named: at the timeout
    src.keep([rms(5, 1500)])
    src.wake_at(5000, 25000.0)
    time.sleep(0.3)
    assert [f.seq for f in next(batches)] == [5]                      # waited hold_s: out
    src.keep([rms(6, 1750)])
    src._stopped = True                                               # stopped: what waits, once
    assert [[f.seq for f in b] for b in batches] == [[6]]


def moving_clock():
    """A wall clock at 10**18 ns when first read, going on with the monotonic one from there (a
    wall clock that stood still while time went on is a step back to the daemon's loop)."""
    start: list[int] = []

    def now() -> int:
        m = time.monotonic_ns()
        if not start:
            start.append(m)
        return 10**18 + m - start[0]
    return now


def test_the_loop_takes_one_call_per_rms_decision_and_gives_the_messages_of_one_frame_per_call():
    """The daemon's own batch step (live._process) on RMS frames: one Processor call per
    decision (the frames past its block wait for the next decision's, source.keep), the
    messages and their order in the file those of one frame per call."""
    from cmsensord.config import config_from_dict
    from cmsensord.service.live import _process, _Watch
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario("faulty", n_channels=4, duration_s=8.0, seed=3)   # one STATUS frame, at boot:
    data = Board(sc, BoardConfig(n_channels=4, mode="rms", status_every_s=60.0)).generate(8.0)  # RMS only
    cfg = config_from_dict({"link": {"max_drift_s": 0.0}, "channels": [{"name": f"ch{i}", "index": i}
                                                                       for i in range(4)]})
    frames, _ = iter_frames(data)
    one = one_frame_per_call(frames, cfg)

    batched, calls = ListSink(), []
    proc = Processor(cfg, batched, clock_ns=moving_clock())     # the loop looks for wall-clock steps
    handle = proc.handle
    proc.handle = lambda part: (calls.append(len(part)), handle(part))   # type: ignore[method-assign]
    step = len(data) // 23                          # reads of ~0.35 s, cut anywhere
    port = PacedPort([data[k:k + step] for k in range(0, len(data), step)], pause=0.05)
    with SerialSource("/dev/fake", baud=921600, open_port=lambda: port) as src:
        watch = _Watch(cfg, proc, src, None, None)
        for batch in src:
            _process(cfg, proc, src, watch, None, batch)
            if not port.reads and not batch and not src.waiting:
                break
        src.stop()
        for batch in src:
            proc.handle(batch)
    proc.finish()

    assert sum(calls) == len(frames)
    decisions = len(one.topic("/cm/ch0/severity"))
    assert decisions >= 6
    assert len([n for n in calls if n]) <= decisions + 2, calls     # not two a decision (output_parts)
    assert by_topic(one.messages) == by_topic(batched.messages)
    assert [(t, s) for t, s, _ in one.messages] == [(t, s) for t, s, _ in batched.messages]


def test_live_rms_on_a_pty_equals_the_replay_of_its_capture(tmp_path):
    """The daemon at 1x in RMS mode (one wake-up a decision, the frames past a decision's block
    kept for the next, the reader's 1-s holds) writes the messages a replay of its capture writes."""
    a, b = _live_and_replay(tmp_path, ("--mode", "rms", "--channels", "4", "--duration", "6"), 1.5,
                            config="channels:\n" + "".join(f"  - {{name: ch{i}, index: {i}}}\n" for i in range(4)))
    assert len(a["/cm/ch3/severity"]) >= 3
    assert a == b
