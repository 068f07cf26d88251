"""The bounded frame queue and the serial reader thread on a real pty."""

from __future__ import annotations

import os
import threading
import time
import tty

from cmsensord.frame_queue import FrameQueue
from cmsensord.link import SerialReader
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


def raw(i, chan=0):
    return Frame(FrameType.RAW, i & 0xFFFF, i * 250, chan, 0, b"\0\0" * 250)


def test_a_full_queue_drops_the_oldest_raw_frames_first():
    q = FrameQueue(10)
    q.put([raw(0), frame(1), raw(2), raw(3), frame(4), raw(5)])
    q.put([frame(6), raw(7), frame(8), raw(9), frame(10), frame(11)])   # 12 > 10: two RAW go
    got = q.get(timeout=0)
    assert [f.seq for f in got] == [1, 3, 4, 5, 6, 7, 8, 9, 10, 11]
    assert (q.drops, q.raw_drops) == (2, 2)
    # no RAW left to drop: then the oldest frames of any type
    q.put([frame(i) for i in range(20, 33)])
    assert [f.seq for f in q.get(timeout=0)] == list(range(23, 33))
    assert (q.drops, q.raw_drops) == (5, 2)


def test_a_stalled_loop_loses_raw_blocks_but_no_rms_frame_and_memory_stays_bounded():
    """A real reader thread on a pty; the loop stalls while the board sends bursts of 100
    blocks (one RAW, one RMS and one TACHO frame each: 300 frames) into a queue of 256:
    exactly 44 RAW frames per burst are shed, every RMS and TACHO frame is delivered."""
    from cmsensord.protocol import encode_frame, encode_tacho

    master, slave = os.openpty()
    tty.setraw(slave)
    q = FrameQueue(256)
    reader = SerialReader(os.ttyname(slave), baud=921600, read_size=4096, queue=q)
    reader.start()
    assert reader.connected.wait(5.0)
    payload = b"\1\0" * 250
    got, depth = [], 0
    for burst in range(3):
        for i in range(burst * 100, burst * 100 + 100):
            os.write(master, encode_frame(FrameType.RAW, (3 * i) & 0xFFFF, i * 250, 0, 0, payload)
                     + encode_rms((3 * i + 1) & 0xFFFF, i * 250, [1.0])
                     + encode_tacho((3 * i + 2) & 0xFFFF, i * 250, 0, []))
        deadline = time.monotonic() + 5.0      # the stalled loop: the reader goes on reading
        while reader.decoder.counters.frames["tacho"] < 100 * (burst + 1) and time.monotonic() < deadline:
            time.sleep(0.01)
        depth = max(depth, len(q))
        got += q.get(timeout=0)
    reader.stop()
    reader.join(timeout=2.0)
    os.close(master)
    os.close(slave)
    kinds = [f.type for f in got]
    assert kinds.count(FrameType.RMS) == 300 and kinds.count(FrameType.TACHO) == 300
    assert q.raw_drops == q.drops == 3 * 44
    assert kinds.count(FrameType.RAW) == 300 - 3 * 44
    assert depth == 256
    # the RAW frames kept are the newest of each burst
    raw_t0 = [f.t0 // 250 for f in got if f.type == FrameType.RAW]
    assert raw_t0[:56] == list(range(44, 100))


def test_a_port_whose_device_comes_back_is_reopened_at_once_not_after_the_back_off(tmp_path):
    """The device is gone (cannot open); it appears 0.3 s later: the reader tries again then,
    not when its 5-s back-off ends, and says link_lost, then link_restored."""
    import serial

    port = tmp_path / "ttyBOARD"
    opened = threading.Event()

    class Port:
        in_waiting = 0

        def read(self, n):
            time.sleep(0.01)
            return b""

        def close(self):
            pass

    def open_port():
        if not port.exists():
            raise serial.SerialException(f"could not open port {port}: No such file or directory")
        opened.set()
        return Port()

    q = FrameQueue(100)
    reader = SerialReader(str(port), baud=921600, read_size=4096, queue=q, open_port=open_port,
                          reconnect_min_s=5.0, reconnect_max_s=5.0)
    reader.start()
    try:
        time.sleep(0.3)
        port.write_bytes(b"")
        t = time.monotonic()
        assert opened.wait(4.0) and time.monotonic() - t < 4.0
        assert [kind for _, kind, _ in reader.events] == ["link_lost", "link_restored"]
    finally:
        reader.stop()
        reader.join(timeout=2)


def test_a_tty_backlog_is_read_before_the_reader_waits_and_a_block_in_one_read():
    """A tty shows at most 4095 bytes at a time: of 6 kB waiting, a read that got that much says
    more may wait (so the reader does not hold before the rest), the read of the rest says no
    more; a block that comes while the reader waits is one read of the whole block (select on
    the port), not its first byte and then the rest."""
    import serial

    master, slave = os.openpty()
    tty.setraw(slave)
    ser = serial.Serial(os.ttyname(slave), 921600, timeout=0.5)
    reader = SerialReader(ser.port, baud=921600, read_size=4096, queue=FrameQueue(100))
    try:
        data = bytes(range(256)) * 24
        assert os.write(master, data) == len(data)
        got, steps = b"", []
        while len(got) < len(data):
            chunk, more = reader._read(ser)
            got += chunk
            steps.append((len(chunk), more))
        assert got == data
        # the first read stopped at the tty's 4095 bytes: more may wait (the rest came in the
        # same step when the tty showed it at once)
        assert steps in ([(4095, True), (len(data) - 4095, False)], [(len(data), False)]), steps
        threading.Timer(0.1, os.write, (master, data[:600])).start()
        assert reader._read(ser) == (data[:600], False)
    finally:
        ser.close()
        os.close(master)
        os.close(slave)
