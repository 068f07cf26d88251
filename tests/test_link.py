"""The bounded frame queue and the serial reader thread on a real pty."""

from __future__ import annotations

import os
import threading
import time
import tty

from cmsensord.link import FrameQueue, SerialReader
from cmsensord.protocol import Frame, FrameType, encode_rms


def frame(i):
    return Frame(FrameType.RMS, i & 0xFFFF, i * 250, 1, 0, b"\0\0\0\0")


def test_queue_is_bounded_drops_the_oldest_and_counts():
    q = FrameQueue(16)
    q.put([frame(i) for i in range(10)])
    q.put([frame(i) for i in range(10, 30)])
    assert len(q) == 16 and q.drops == 14
    got = q.get(timeout=0)
    assert [f.seq for f in got] == list(range(14, 30))
    assert len(q) == 0


def test_queue_get_waits_for_frames_or_times_out():
    q = FrameQueue(16)
    t0 = time.monotonic()
    assert q.get(timeout=0.2) == []
    assert time.monotonic() - t0 >= 0.15
    threading.Timer(0.05, lambda: q.put([frame(1)])).start()
    assert [f.seq for f in q.get(timeout=2.0)] == [1]


def test_reader_thread_decodes_a_pty_and_tees_the_capture(tmp_path):
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    data = b"".join(encode_rms(i, i * 250, [1.0, 2.0]) for i in range(200))
    q = FrameQueue(1000)
    with open(tmp_path / "cap.bin", "wb") as cap:
        reader = SerialReader(path, baud=921600, read_size=4096, queue=q, capture=cap)
        reader.start()
        assert reader.connected.wait(5.0)
        os.write(master, data)
        got = []
        deadline = time.monotonic() + 5.0
        while len(got) < 200 and time.monotonic() < deadline:
            got += q.get(timeout=0.1)
        reader.stop()
        reader.join(timeout=2.0)
    os.close(master)
    os.close(slave)
    assert [f.seq for f in got] == list(range(200))
    assert reader.decoder.counters.crc_failures == 0
    assert (tmp_path / "cap.bin").read_bytes() == data
