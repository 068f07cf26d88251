"""A store-and-forward queue an earlier run left, damaged, through ``cmsensord replay --publish``
against a real Mosquitto broker (tests/mosquitto.py): a bad byte in the middle of a segment
costs its record only, the messages after it are sent and their seq numbers are not used
again; an unreadable acknowledgement cursor sends everything kept, saying so; an entry named
like a segment that is not a file is left alone; a queue directory that cannot be used names
the setting to change."""

from __future__ import annotations

import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from mosquitto import Subscriber, free_port, needs_mosquitto
from processes import ENV, cmsensord
from test_mqtt import broker, mqtt_yaml, seqs  # noqa: F401 - broker: a fixture

pytestmark = needs_mosquitto


def _capture(path: Path, duration: int) -> Path:
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "faulty", "--duration", str(duration),
                    "--out", str(path)], check=True, capture_output=True, env=ENV, timeout=60)
    return path


@pytest.fixture(scope="module")
def earlier(tmp_path_factory) -> tuple[Path, int]:
    """The queue a replay left with no broker listening (it waited 10 s for one), and how many
    messages it holds (seqs 1 to that)."""
    work = tmp_path_factory.mktemp("earlier")
    cfg = work / "site.yaml"
    cfg.write_text(mqtt_yaml(free_port(), f"queue_dir: {work / 'q'}"))
    p = cmsensord("replay", str(_capture(work / "cap.bin", 20)), "--config", str(cfg), "--out", str(work / "out"),
                  "--publish")
    assert p.returncode == 0, p.stderr
    left = int(p.stderr.split(" acknowledged; ")[1].split(" left")[0])
    assert left > 50 and [f.name for f in (work / "q").glob("q-*.seg")] == ["q-00000000000000000001.seg"]
    return work / "q", left


def _replay(tmp_path: Path, port: int, queue: Path, *args: str) -> subprocess.CompletedProcess:
    """``replay --publish`` of a 5 s capture with ``queue`` as ``mqtt.queue_dir``."""
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(port, f"queue_dir: {queue}"))
    return cmsensord(*args, "replay", str(_capture(tmp_path / "cap.bin", 5)), "--config", str(cfg),
                     "--out", str(tmp_path / "out"), "--publish")


def _all_sent(p: subprocess.CompletedProcess, port: int) -> int:
    """How many messages the run sent, each acknowledged, none left."""
    assert p.returncode == 0, p.stderr
    sent = int(p.stderr.split("  mqtt: ")[1].split(" message(s)")[0])
    assert f"  mqtt: {sent} message(s) sent to 127.0.0.1:{port} as client_id rig1, {sent} acknowledged; 0 left " \
           "unacknowledged in " in p.stderr, p.stderr
    return sent


def _record_around(data: bytes, at: int) -> tuple[int, int]:
    """The seq and the size of the record holding byte ``at`` of a segment."""
    pos = 0
    while True:
        length = struct.unpack_from("<I", data, pos)[0]
        if pos + 8 + length > at:
            return struct.unpack_from("<Q", data, pos + 8)[0], 8 + length
        pos += 8 + length


def test_a_bad_byte_mid_segment_costs_its_record_only(tmp_path, earlier, broker):  # noqa: F811
    """Not a torn tail: the valid messages after it stay queued and are sent, and their seq
    numbers are not given to new ones."""
    queue = tmp_path / "q"
    shutil.copytree(earlier[0], queue)
    segment = queue / "q-00000000000000000001.seg"
    data = bytearray(segment.read_bytes())
    at = len(data) // 4
    lost, size = _record_around(data, at)
    data[at] ^= 0xFF
    segment.write_bytes(bytes(data))
    sub = Subscriber(broker.port)
    try:
        p = _replay(tmp_path, broker.port, queue)
        assert (f"WARNING mqtt_queue: store-and-forward queue: skipped {size} damaged byte(s) in its segments (1 "
                "message(s) lost); the messages after them are kept") in p.stderr.splitlines(), p.stderr
        assert "torn" not in p.stderr
        sent = _all_sent(p, broker.port)
        assert sent > earlier[1]
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= sent)
        assert sorted(set(seqs(sub))) == [s for s in range(1, sent + 2) if s != lost]
    finally:
        sub.close()


def test_records_a_power_cut_zeroed_at_the_end_give_their_seqs_to_no_new_message(tmp_path, earlier, broker):  # noqa: F811
    """The last records of the newest segment zero-filled (a power cut within ``fsync_s`` of
    their writes; they may have been sent from the page cache): every seq they held is retired,
    so a subscriber de-duplicating by seq drops no new message as a repeat."""
    queue = tmp_path / "q"
    shutil.copytree(earlier[0], queue)
    segment = queue / "q-00000000000000000001.seg"
    data = bytearray(segment.read_bytes())
    starts = [0]
    while starts[-1] < len(data):
        starts.append(starts[-1] + 8 + struct.unpack_from("<I", data, starts[-1])[0])
    cut = starts[-5]                                    # the last four records
    data[cut:] = bytes(len(data) - cut)
    segment.write_bytes(bytes(data))
    sub = Subscriber(broker.port)
    try:
        p = _replay(tmp_path, broker.port, queue)
        torn = -(-(len(data) - cut) // 19)
        assert (f"WARNING mqtt_queue: store-and-forward queue: cut {len(data) - cut} byte(s) of torn record(s) at "
                f"its end (a crash or a power cut while writing; the {torn} seq(s) they could hold are not used "
                "again)") in p.stderr.splitlines(), p.stderr
        sent = _all_sent(p, broker.port)
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= sent)
        got = sorted(set(seqs(sub)))
        assert got[:earlier[1] - 4] == list(range(1, earlier[1] - 3)), got[:earlier[1]]
        assert got[earlier[1] - 4] == earlier[1] - 3 + torn, got[earlier[1] - 6:earlier[1]]   # 4 used before
    finally:
        sub.close()


def test_an_unreadable_acknowledgement_cursor_is_said_and_everything_kept_is_sent(tmp_path, earlier, broker):  # noqa: F811
    """One warning, counted as an event, says the cursor is unreadable and that what is kept is
    sent again; the cursor is written again once the broker has acknowledged them."""
    queue = tmp_path / "q"
    shutil.copytree(earlier[0], queue)
    (queue / "acked").write_text("garbage\n")
    sub = Subscriber(broker.port)
    try:
        p = _replay(tmp_path, broker.port, queue, "-v")
        said = [ln for ln in p.stderr.splitlines() if " mqtt_queue: " in ln]
        assert said == [f"WARNING mqtt_queue: store-and-forward queue: the acknowledgement cursor {queue / 'acked'} "
                        f"is unreadable (not a number: 'garbage'): the {earlier[1]} queued message(s) are sent from "
                        "the oldest kept, some perhaps a second time (delivery is at least once)"], p.stderr
        assert ", mqtt_queue 1" in p.stderr, p.stderr
        sent = _all_sent(p, broker.port)
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= sent)
        assert sorted(set(seqs(sub))) == list(range(1, sent + 1))
        assert (queue / "acked").read_text() == f"{sent}\n"
    finally:
        sub.close()


def test_a_directory_named_like_a_segment_is_left_alone(tmp_path, earlier, broker):  # noqa: F811
    """Said and skipped, not a reason to stop (exit 78: a daemon under systemd is not restarted):
    the queue's own segments are all it reads."""
    queue = tmp_path / "q"
    shutil.copytree(earlier[0], queue)
    stray = queue / "q-00000000000000000000.seg"
    stray.mkdir()
    sub = Subscriber(broker.port)
    try:
        p = _replay(tmp_path, broker.port, queue)
        assert (f"WARNING mqtt_queue: store-and-forward queue: {stray} is a directory, not one of its segment "
                "files: left alone") in p.stderr.splitlines(), p.stderr
        sent = _all_sent(p, broker.port)
        assert sent > earlier[1]
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= sent)
        assert sorted(set(seqs(sub))) == list(range(1, sent + 1))
        assert stray.is_dir()
    finally:
        sub.close()


@pytest.mark.parametrize("setting", ["mqtt.queue_dir", "output.dir"])
def test_a_queue_directory_that_is_a_file_names_the_setting_to_change(tmp_path, setting):
    """Exit 78 with one line: 'not a directory', and ``mqtt.queue_dir`` when that is set (else
    output.dir or --out, where the queue is)."""
    out = tmp_path / "out"
    out.mkdir()
    queue = tmp_path / "q" if setting == "mqtt.queue_dir" else out / "mqtt-queue"
    queue.write_text("not a directory\n")
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(free_port(), *([f"queue_dir: {queue}"] if setting == "mqtt.queue_dir" else [])))
    p = cmsensord("replay", str(_capture(tmp_path / "cap.bin", 5)), "--config", str(cfg), "--out", str(out),
                  "--publish")
    assert p.returncode == 78, p.stderr
    if setting == "mqtt.queue_dir":
        want = (f"cmsensord: configuration error: {cfg}: mqtt.queue_dir: {queue}: cannot use the MQTT queue "
                "directory: not a directory (set mqtt.queue_dir to a directory it can write)")
    else:
        want = (f"cmsensord: output error: {queue}: cannot use the MQTT queue directory: not a directory (set "
                "output.dir or --out to a writable directory)")
    assert p.stderr.splitlines() == [want], p.stderr
