"""The store-and-forward queue of the MQTT publisher (cmsensord/publish/disk_queue.py): order,
acknowledgements, a torn record after a crash, a damaged record mid-segment, the acknowledgement
cursor unreadable or behind, entries named like segments, the bound, a full disk (/dev/full
under its file: the records held in memory and sent from there)."""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path

import pytest

from cmsensord.config.mqtt import MqttConfig
from cmsensord.publish.disk_queue import DiskQueue
from cmsensord.publish.seq_lease import LEASE
from cmsensord.publish.topics import TopicMap, payload


def fill(q: DiskQueue, n: int, size: int = 100) -> list[int]:
    return [q.append(f"p/ch0/severity/{i}", lambda seq, i=i: b"x" * size + str(i).encode(), i % 2 == 0)
            for i in range(n)]


def test_records_come_back_in_order_and_a_reconnection_resends_only_the_unacknowledged(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=1000)
    assert fill(q, 30) == list(range(1, 31))
    first = q.next_batch(10)
    assert [r.seq for r in first] == list(range(1, 11))
    assert first[3].topic == "p/ch0/severity/3" and first[3].payload.endswith(b"3") and not first[3].retain
    for seq in (2, 1, 4):                       # out of order: the cursor stops before 3
        q.ack(seq)
    assert q.acked == 2 and q.depth == 28
    q.rewind()
    assert [r.seq for r in q.next_batch(3)] == [3, 4, 5]
    for seq in range(3, 21):
        q.ack(seq)
    assert q.acked == 20 and min(s.first for s in q.segments) > 1      # acknowledged segments gone
    q.close()


def test_a_torn_record_is_cut_off_and_numbering_goes_on_after_a_restart(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 5)
    q.ack(1)
    q.close()
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    whole = seg.read_bytes()
    seg.write_bytes(whole + whole[:40])         # a crash in the middle of the next record
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.truncated_bytes == 40 and q.damaged_bytes == 0 and seg.stat().st_size == len(whole)
    assert q.acked == 1 and q.depth == 4 and [r.seq for r in q.next_batch(10)] == [2, 3, 4, 5]
    assert q.torn_seqs == 3                                 # 40 bytes: two 19-byte records and a part
    assert q.append("t", lambda seq: b"{}", False) == 9     # 6-8 the torn records' could be: maybe sent
    for seq in (2, 3, 4, 5, 9):
        q.ack(seq)
    assert q.acked == 9 and q.depth == 0
    q.close()


def _flip(path, at: int) -> None:
    data = bytearray(path.read_bytes())
    data[at] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("where", [0, 5, 10, 25, -1], ids=["length", "crc", "seq", "topic", "payload"])
def test_a_damaged_record_mid_segment_costs_itself_only(tmp_path, where):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 10)
    q.close()
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    size = seg.stat().st_size // 10             # the 10 records are of one size
    _flip(seg, 3 * size + (where % size))       # in the 4th record
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert (q.damaged_bytes, q.damaged_records, q.truncated_bytes) == (size, 1, 0)
    assert q.depth == 9 and [r.seq for r in q.next_batch(20)] == [1, 2, 3, 5, 6, 7, 8, 9, 10]
    assert q.append("t", lambda seq: b"{}", False) == 11
    for seq in (1, 2, 3, 5, 6, 7, 8, 9, 10):   # the cursor moves over the damaged record
        q.ack(seq)
    assert q.acked == 10 and q.depth == 1
    q.close()


def test_damage_in_acknowledged_records_changes_no_count(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 10)
    for seq in range(1, 11):
        q.ack(seq)
    q.close()
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    _flip(seg, seg.stat().st_size // 2)
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.damaged_records == 1 and q.acked == 10 and q.depth == 0 and not q.segments
    assert q.append("t", lambda seq: b"{}", False) == 11 and q.depth == 1
    q.close()


def test_the_bound_counts_only_the_records_it_drops(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=1000)
    fill(q, 30)
    q.close()
    _flip(sorted(tmp_path.glob("q-*.seg"))[0], 200)             # the 2nd record
    q = DiskQueue(tmp_path, max_bytes=3000, segment_bytes=1000)
    assert q.damaged_records == 1 and q.depth == 29
    fill(q, 10)
    assert q.dropped > 0 and q.dropped + q.depth == 29 + 10
    q.close()


def test_zeros_over_records_mid_segment_are_skipped(tmp_path):
    """A run of zeros, as a power cut can leave, over the 4th and 5th records and into the 6th."""
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 10)
    q.close()
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    data, size = seg.read_bytes(), seg.stat().st_size // 10
    seg.write_bytes(data[:3 * size] + bytes(2 * size + 30) + data[5 * size + 30:])
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert (q.damaged_bytes, q.damaged_records) == (3 * size, 3)
    assert [r.seq for r in q.next_batch(20)] == [1, 2, 3, 7, 8, 9, 10]
    q.close()


def test_a_cursor_behind_the_oldest_segment_moves_up_to_it(tmp_path):
    """A kill -9 after acknowledged segments were deleted and before the cursor was saved: the
    records before the oldest segment are not counted as queued, and acknowledgements move the
    cursor on."""
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=1000)
    fill(q, 30)
    for seq in range(1, 21):
        q.ack(seq)
    oldest = q.segments[0].first
    q.close()
    (tmp_path / "acked").write_text("3\n")
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=1000)
    assert q.cursor_error is None and q.acked == oldest - 1 and q.depth == 30 - q.acked
    for seq in range(oldest, 31):
        q.ack(seq)
    assert q.acked == 30 and q.depth == 0
    q.close()


@pytest.mark.parametrize(("text", "why"), [("garbage\n", "not a number: 'garbage'"), ("", "empty"),
                                           ("-4\n", "not a number: '-4'")])
def test_an_unreadable_cursor_is_said_and_rewritten(tmp_path, text, why):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 5)
    q.ack(1)
    q.close()
    (tmp_path / "acked").write_text(text)
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.cursor_error == why and q.acked == 0 and q.depth == 5      # from the oldest kept
    assert q.append("t", lambda seq: b"{}", False) == 6
    q.close()
    assert (tmp_path / "acked").read_text() == "0\n"
    assert DiskQueue(tmp_path, max_bytes=1 << 20).cursor_error is None


def test_entries_named_like_segments_that_are_not_are_left_alone(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 5)
    q.close()
    (tmp_path / "q-00000000000000000006.seg").mkdir()          # the name of the next segment
    os.mkfifo(tmp_path / "q-00000000000000000009.seg")
    (tmp_path / "q-notes.seg").write_text("mine\n")
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert [(p.name, what) for p, what in q.strays] == [
        ("q-00000000000000000006.seg", "a directory"),
        ("q-00000000000000000009.seg", "a special file (FIFO, socket or device)"),
        ("q-notes.seg", "named unlike its segments (q-<first seq in 20 digits>.seg)")]
    assert q.append("t", lambda seq: b"{}", False) == 7        # 6: its segment's name is taken
    assert q.depth == 6 and [r.seq for r in q.next_batch(10)] == [1, 2, 3, 4, 5, 7]
    q.close()
    assert (tmp_path / "q-notes.seg").read_text() == "mine\n"


def test_a_corrupt_record_ends_the_segment_there(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 3)
    q.close()
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    data = bytearray(seg.read_bytes())
    data[-5] ^= 0xFF                            # a bit flip in the last record's payload
    seg.write_bytes(bytes(data))
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert [r.seq for r in q.next_batch(10)] == [1, 2]
    q.close()


def test_the_bound_drops_the_oldest_segment_and_counts_its_unsent_records(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=5000, segment_bytes=1000)
    fill(q, 100)
    assert q.size_bytes <= 5000 + 1000
    assert q.dropped == q.acked > 0
    assert q.depth == 100 - q.dropped
    assert q.next_batch(1)[0].seq == q.dropped + 1
    q.close()


def test_a_full_disk_holds_the_records_in_memory_sends_them_and_writes_them_when_it_takes_data(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 2)
    saved = os.dup(q._fd)
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, q._fd)
    try:
        assert fill(q, 3) == [3, 4, 5]
        assert q.write_error is not None and q.write_error.errno == 28
        assert q.depth == 5 and [r.seq for r in q.next_batch(10)] == [1, 2, 3, 4, 5]     # sent from memory
        q.ack(1)
        q.ack(3)
        q.write_held()
        assert q.write_error is not None and q.held_unsent == 3
    finally:
        os.dup2(saved, q._fd)
        os.close(full)
        os.close(saved)
    q.write_held()
    assert q.write_error is None and q.held_unsent == 0
    q.ack(2)                                    # the cursor moves to 3: the rest on the disk
    q.close()
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.acked == 3 and [r.seq for r in q.next_batch(10)] == [4, 5] and q.next_seq == 6
    q.close()


def test_a_run_after_a_crash_numbers_above_the_seq_lease_and_after_a_clean_stop_goes_on(tmp_path):
    """Records sent before they were durable (a power cut takes them, or the disk refused them):
    the next run gives none of their seqs to a new message; after a clean stop, no gap."""
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    fill(q, 5)
    assert [r.seq for r in q.next_batch(10)] == [1, 2, 3, 4, 5]
    seg = sorted(tmp_path.glob("q-*.seg"))[-1]
    seg.write_bytes(seg.read_bytes()[:0])       # a power cut: nothing of them reached the disk
    q = DiskQueue(tmp_path, max_bytes=1 << 20)  # the crashed run never closed
    assert q.next_seq == LEASE + 1 and q.depth == 0
    assert q.append("t", lambda seq: b"{}", False) == LEASE + 1
    q.ack(LEASE + 1)
    assert q.acked == LEASE + 1
    q.close()
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.next_seq == LEASE + 2              # a clean stop: numbering goes on
    q.close()


def test_a_disk_that_refuses_is_one_error_until_it_takes_a_record(tmp_path, monkeypatch):
    """Held records the broker acknowledged need the disk no more: that is no sign it takes data
    again; a segment it cannot delete, and a stop it cannot sync, are no errors."""
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=200)
    fill(q, 3)
    full = os.open("/dev/full", os.O_WRONLY)
    saved = os.dup(q._fd)
    os.dup2(full, q._fd)
    try:
        fill(q, 2)
        assert q.write_error is not None
        for rec in q.next_batch(10):
            q.ack(rec.seq)
        q.write_held()
        assert q.held_unsent == 0 and q.write_error is not None
    finally:
        os.dup2(saved, q._fd)
        os.close(full)
        os.close(saved)

    def read_only(self, missing_ok=False):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(Path, "unlink", read_only)
    fill(q, 3)                                  # a new segment; the acknowledged ones stay on the disk
    assert q.write_error is None
    for rec in q.next_batch(10):
        q.ack(rec.seq)
    assert q.acked == 8
    (tmp_path / "acked.tmp").mkdir()            # the cursor cannot be written
    q.close()
    assert isinstance(q.write_error, IsADirectoryError)


def test_records_held_past_the_memory_bound_are_dropped_and_counted(tmp_path, monkeypatch):
    monkeypatch.setattr("cmsensord.publish.disk_queue.HOLD_BYTES", 1000)
    q = DiskQueue(tmp_path / "q", max_bytes=1 << 20)
    (tmp_path / "q").rmdir()
    (tmp_path / "q").write_text("not a directory")       # the disk refuses every record
    fill(q, 30)                                 # ~320 bytes each held (payload, topic, objects): 3 fit in 1000
    assert q.write_error is not None
    assert q.dropped == 27 and q.depth == 3 and [r.seq for r in q.next_batch(20)] == [28, 29, 30]
    q.close()
    assert len(q._gaps) == 1                    # the dropped seqs: one range, however many


def test_the_publisher_reports_a_full_disk_once_sends_from_memory_and_resumes(tmp_path):
    pytest.importorskip("paho.mqtt")
    from cmsensord.publish.publisher import Publisher

    pub = Publisher(MqttConfig(host="127.0.0.1", port=9, client_id="t", publish=("events",),
                               reconnect_min_s=5.0), str(tmp_path / "q"))
    pub.start()
    try:
        pub.offer("/cm/events", 10**18, {"kind": "start", "message": "first"})
        assert _wait(lambda: pub.queue.next_seq == 2 and pub.queue._fd is not None)     # numbered, then written
        saved, full = os.dup(pub.queue._fd), os.open("/dev/full", os.O_WRONLY)
        os.dup2(full, pub.queue._fd)
        for i in range(5):
            pub.offer("/cm/events", 10**18, {"kind": "stop", "message": str(i)})
        assert _wait(lambda: any(e[3].get("action") == "write_error" for e in list(pub.events)))
        time.sleep(0.3)
        errors = [e for e in list(pub.events) if e[0] == "mqtt_queue"]
        assert [e[1] for e in errors] == [f"store-and-forward queue {tmp_path / 'q'}: cannot write "
                                          "(No space left on device); new messages are sent from memory, up to "
                                          "4 MB kept until it takes them"]
        assert len(pub.handover) == 0 and pub.queue.next_seq == 7 and pub.queue.held_unsent == 5
        os.dup2(saved, pub.queue._fd)
        assert _wait(lambda: pub.queue.held_unsent == 0)
        assert [e[3].get("action") for e in list(pub.events) if e[0] == "mqtt_queue"] == \
            ["write_error", "resumed"]
        os.close(full)
        os.close(saved)
    finally:
        pub.close()


def test_topics_mirror_the_mcap_topics_and_the_payload_carries_seq():
    topics = TopicMap(MqttConfig(host="h", client_id="rig1", publish=("severity", "events")))
    assert topics.route("/cm/ch0/severity") == ("cmsensord/rig1/ch0/severity", True)
    assert topics.route("/cm/events") == ("cmsensord/rig1/events", False)
    assert topics.route("/cm/ch0/akf") is None and topics.route("/cm/diagnostics") is None
    assert payload("/cm/events", 1_500_000_000_000_000_001, {"kind": "x", "v": float("nan")}, 7) == \
        b'{"timestamp":{"sec":1500000000,"nsec":1},"kind":"x","seq":7}'   # as in the MCAP: NaN absent


def _wait(test, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if test():
            return True
        time.sleep(0.02)
    return test()


def test_default_yaml_documents_every_mqtt_key_with_its_default():
    import dataclasses
    from pathlib import Path

    import yaml

    text = (Path(__file__).resolve().parents[1] / "config" / "default.yaml").read_text()
    block = text[text.index("# mqtt:\n"):]
    data = yaml.safe_load("\n".join(line[2:] for line in block.splitlines()))["mqtt"]
    fields = {f.name: f.default for f in dataclasses.fields(MqttConfig)}
    assert set(data) == set(fields)
    cfg = MqttConfig(**{**data, "publish": tuple(data["publish"])})
    assert all(getattr(cfg, k) == v for k, v in fields.items() if k != "host")


def test_a_full_hand_over_queue_drops_the_oldest_with_an_event(tmp_path):
    pytest.importorskip("paho.mqtt")
    from cmsensord.publish.publisher import Publisher

    pub = Publisher(MqttConfig(host="127.0.0.1", port=9, client_id="t", publish=("events",),
                               handover_messages=16, reconnect_min_s=5.0), str(tmp_path / "q"))
    for i in range(20):                         # before the thread runs: 4 too many
        pub.offer("/cm/events", 10**18, {"kind": "start", "message": str(i)})
    pub.start()
    try:
        assert _wait(lambda: pub.queue.next_seq == 17)
        assert _wait(lambda: any(e[3].get("action") == "handover_dropped" for e in list(pub.events)))
        dropped = [e for e in list(pub.events) if e[3].get("action") == "handover_dropped"]
        assert [(e[1], e[3]["count"]) for e in dropped] == [
            ("the publisher fell behind: dropped the 4 oldest message(s) waiting in memory (4 in all)", 4)]
        assert b'"message":"4"' in pub.queue.next_batch(1)[0].payload       # 0..3 were dropped
    finally:
        pub.close()


def _publisher(tmp_path):
    pytest.importorskip("paho.mqtt")
    from cmsensord.publish.publisher import Publisher

    return Publisher(MqttConfig(host="127.0.0.1", port=9, client_id="t", publish=("events",)), str(tmp_path / "q"))


def test_a_segment_that_cannot_be_read_is_one_error_until_it_can(tmp_path, monkeypatch):
    """The publisher thread's passes (each POLL_S) with the queue unreadable: one read_error, no
    write error, and one INFO when it reads again."""
    pub = _publisher(tmp_path)
    pub.offer("/cm/events", 10**18, {"kind": "start", "message": "x"})
    pub._to_disk()
    sent = []

    class Client:
        def publish(self, topic, payload, qos, retain):
            sent.append(topic)
            return type("Info", (), {"mid": len(sent)})()

    pub._client, pub.state = Client(), "connected"
    read = pub.queue.next_batch

    def unreadable(n):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(pub.queue, "next_batch", unreadable)
    for _ in range(5):                          # what _run does each pass
        pub._to_disk()
        pub._send(0.0)
    monkeypatch.setattr(pub.queue, "next_batch", read)
    pub._to_disk()
    pub._send(0.0)
    said = [(e[3]["action"], e[1]) for e in pub.events if e[0] == "mqtt_queue"]
    assert said == [("read_error", f"store-and-forward queue {tmp_path / 'q'}: cannot read (Input/output error); "
                                   "sending waits until it can"),
                    ("resumed", "store-and-forward queue readable again")], said
    assert sent == ["cmsensord/t/events"]
    pub.queue.close()


def test_a_seq_lease_that_cannot_be_written_is_said(tmp_path):
    pub = _publisher(tmp_path)
    (tmp_path / "q" / "seq-lease.tmp").mkdir()  # a stray: the lease alone cannot be written
    pub.offer("/cm/events", 10**18, {"kind": "start", "message": "x"})
    pub._to_disk()
    said = [e[1] for e in pub.events if e[0] == "mqtt_queue"]
    assert said == [f"store-and-forward queue {tmp_path / 'q'}: cannot write its seq lease (Is a directory): after "
                    "a crash, seqs may be used again"], said
    pub.queue.close()


def test_a_segment_deleted_under_the_queue_is_counted_and_sending_goes_on(tmp_path):
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=300)
    fill(q, 9)                                  # three segments of three records
    first, second = sorted(tmp_path.glob("q-*.seg"))[:2]
    q.close()
    q = DiskQueue(tmp_path, max_bytes=1 << 20, segment_bytes=300)
    second.unlink()
    assert [r.seq for r in q.next_batch(10)] == [1, 2, 3, 7, 8, 9] and q.dropped == 3
    for seq in (1, 2, 3, 7, 8, 9):
        q.ack(seq)
    assert q.acked == 9 and q.depth == 0        # the cursor moves over the lost seqs
    q.close()


def test_a_held_record_dropped_in_flight_is_counted(tmp_path, monkeypatch):
    """Sent from memory, not acknowledged, then dropped by the bound: a rewind cannot send it again."""
    monkeypatch.setattr("cmsensord.publish.disk_queue.HOLD_BYTES", 1000)
    q = DiskQueue(tmp_path / "q", max_bytes=1 << 20)
    (tmp_path / "q").rmdir()
    (tmp_path / "q").write_text("not a directory")
    fill(q, 3)
    assert [r.seq for r in q.next_batch(10)] == [1, 2, 3]       # in flight
    fill(q, 3)
    assert q.dropped == 3
    q.rewind()
    assert [r.seq for r in q.next_batch(10)] == [4, 5, 6]


def test_a_seq_lease_beyond_a_u64_is_no_lease(tmp_path):
    (tmp_path / "seq-lease").write_text("99999999999999999999999\n")
    q = DiskQueue(tmp_path, max_bytes=1 << 20)
    assert q.append("t", lambda seq: b"{}", False) == 1
    q.close()
