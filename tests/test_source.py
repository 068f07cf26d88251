"""Frame sources: capture files flush at the end, pacing follows the board's clock,
and how the bytes are cut into reads changes nothing downstream."""

from __future__ import annotations

import time

import numpy as np
import pytest

from cmsensord.config import default_config
from cmsensord.errors import LinkError
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import encode_raw, encode_rms
from cmsensord.sinks.memory import ListSink
from cmsensord.source import ByteStreamSource, CaptureSource, Paced, SerialSource
from tests.test_pipeline import FIXED_CLOCK, rms_stream, without_runtime


def frames_of(source) -> list:
    with source:
        return [f for batch in source for f in batch]


def test_capture_source_flushes_the_last_frame_at_the_end(tmp_path):
    """A frame whose end the decoder can only know at end of input comes out with the flush."""
    data = rms_stream(seconds=1, C=2)
    path = tmp_path / "cap.bin"
    path.write_bytes(data)
    src = CaptureSource(path, chunk=1000)
    batches = list(src)
    assert sum(len(b) for b in batches) == 101       # 1 STATUS + 100 RMS
    assert src.bytes_read == len(data) == src.size
    # a frame behind a truncated one comes out only with the flush at end of input
    cut = encode_raw(1, 0, 0, np.zeros(250, dtype=np.uint16))[:20]
    last = encode_rms(2, 250, [1.0, 2.0])
    path.write_bytes(encode_rms(0, 0, [1.0, 2.0]) + cut + last)
    got = list(CaptureSource(path))
    assert [len(b) for b in got] == [1, 1] and got[-1][0].seq == 2

def test_capture_source_errors_are_one_line_link_errors(tmp_path):
    with pytest.raises(LinkError, match="capture file not found"):
        CaptureSource(tmp_path / "missing.bin")
    with pytest.raises(LinkError, match="is a directory"):
        CaptureSource(tmp_path)


def test_capture_source_closes_its_file(tmp_path):
    path = tmp_path / "cap.bin"
    path.write_bytes(rms_stream(seconds=1))
    with CaptureSource(path) as src:
        pass
    assert src._file.closed


@pytest.mark.parametrize("chunk", [1, 7, 999, 1 << 16])
def test_frames_do_not_depend_on_how_the_bytes_are_cut(chunk):
    data = rms_stream(seconds=2, C=3, drop=(17, 18))
    whole = frames_of(ByteStreamSource([data]))
    assert frames_of(ByteStreamSource.of(data, chunk)) == whole


def test_processor_output_is_the_same_through_any_chunking(tmp_path):
    data = rms_stream(seconds=5, spike_from=3)
    path = tmp_path / "cap.bin"
    path.write_bytes(data)
    outs = []
    for chunk in (333, 1 << 16):
        sink = ListSink()
        proc = Processor(default_config(2), sink, clock_ns=FIXED_CLOCK)
        for frames in CaptureSource(path, chunk=chunk):
            proc.handle(frames)
        proc.finish()
        outs.append(without_runtime(sink.messages))
    assert outs[0] == outs[1] and len(outs[0]) > 10


class FakeClock:
    """A clock that only moves when slept on."""

    def __init__(self) -> None:
        self.t = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += s


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_paced_source_follows_the_board_clock_at_speed(speed):
    """2 s of board time (fs and block from STATUS) take 2/speed s on the injected clock."""
    clock = FakeClock()
    src = Paced(ByteStreamSource.of(rms_stream(seconds=2), 500), speed, clock=clock, sleep=clock.sleep)
    n = sum(len(b) for b in src)
    assert n == 2 + 200
    last_t0 = 199 * 250
    assert clock.t - 100.0 == pytest.approx(last_t0 / 25000 / speed)
    assert all(s > 0 for s in clock.sleeps)


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_a_paced_batch_of_seconds_is_handed_on_as_its_frames_are_due(speed):
    """2 s of board time in one read (an RMS capture's chunk holds tens of seconds): each frame
    is handed on at most 20 ms (``SLICE_S``) before its board time / speed (guards against the
    whole read handed on at once, the replay seconds ahead of --realtime)."""
    clock = FakeClock()
    src = Paced(ByteStreamSource.of(rms_stream(seconds=2), 1 << 20), speed, clock=clock, sleep=clock.sleep)
    early = []
    for batch in src:
        early += [(f.t0_unwrapped / 25000 / speed) - (clock.t - 100.0) for f in batch]
    assert len(early) == 202 and max(early) <= 0.02 + 1e-9, max(early)
    assert clock.t - 100.0 == pytest.approx(199 * 250 / 25000 / speed)


def test_paced_source_does_not_sleep_when_processing_is_slower():
    clock = FakeClock()
    src = Paced(ByteStreamSource.of(rms_stream(seconds=1), 500), 1.0, clock=clock, sleep=clock.sleep)
    for _ in src:
        clock.t += 10.0                 # the consumer takes longer than the board's time
    assert clock.sleeps == []


def test_paced_source_passes_the_inner_source_through(tmp_path):
    path = tmp_path / "cap.bin"
    path.write_bytes(rms_stream(seconds=1))
    clock = FakeClock()
    with Paced(CaptureSource(path), 2.0, clock=clock, sleep=clock.sleep) as src:
        list(src)
        assert src.bytes_read == src.size and src.counters.frames["rms"] == 100
    with pytest.raises(ValueError):
        Paced(ByteStreamSource([]), 0.0)


class FakePort:
    """A port that returns the given reads, then nothing (a quiet board)."""

    def __init__(self, reads: list[bytes]):
        self.reads = list(reads)
        self.in_waiting = 0
        self.closed = False

    def read(self, n: int) -> bytes:
        if self.reads:
            return self.reads.pop(0)
        time.sleep(0.01)
        return b""

    def close(self) -> None:
        self.closed = True


def test_serial_source_yields_batches_until_stopped_then_drains(tmp_path):
    """Empty batches while the board is quiet (the loop does its periodic work); after stop()
    the frames still queued come once and iteration ends; the capture holds every byte."""
    data = rms_stream(seconds=1)
    port = FakePort([data[k:k + 700] for k in range(0, len(data), 700)])
    got, empty = [], 0
    with open(tmp_path / "cap.bin", "wb") as cap, \
            SerialSource("/dev/fake", baud=921600, capture=cap, open_port=lambda: port, timeout=0.02) as src:
        for frames in src:
            got += frames
            empty += not frames
            if empty >= 3 and not port.reads:
                break
        src.stop()
        got += [f for batch in src for f in batch]
    assert len(got) == 101 and port.closed
    assert (tmp_path / "cap.bin").read_bytes() == data
    assert src.counters.bytes_received == len(data)
