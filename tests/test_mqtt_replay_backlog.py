"""`cmsensord replay --publish` sends what it offered before it exits: a replay is done long
before the publisher has connected (it sent 234 of 10,908 messages of an hour's capture and
left the rest queued). It waits, saying so in one line, while the broker acknowledges; it
stops waiting when the broker acknowledges nothing for 10 s, or at Ctrl-C, and what is left
stays queued (the summary says how many)."""

from __future__ import annotations

import math
import re
import resource
import signal
import subprocess
import sys
import time

import pytest

from mosquitto import Broker, Subscriber, free_port, needs_mosquitto
from processes import spawn
from test_mqtt import broker, expected, mqtt_yaml, seqs  # noqa: F401 - broker: a fixture
from test_mqtt_runs import capture

pytestmark = needs_mosquitto

SENDING = "mqtt: sending {n:,} message(s) to 127.0.0.1:{port} before exiting ({pace}); Ctrl-C stops waiting, they " \
          "stay queued"
#: how the waiting messages go: unpaced while connected, but for the backlog queued before the connection
UNPACED = "as fast as the broker takes them"
BACKLOG = "the {b:,} queued before the connection at 2000 a second, mqtt.resend_per_s, about {s} s; the rest " + UNPACED
NOT_CONNECTED = "not connected: once it is, they are its backlog, sent at 2000 a second, mqtt.resend_per_s: about {s} s"


def _paces(n: int) -> set[str]:
    """Every true way of saying how ``n`` waiting messages go (which one depends on when the
    publisher connected)."""
    return {UNPACED, NOT_CONNECTED.format(s=math.ceil(n / 2000)),
            *(BACKLOG.format(b=b, s=math.ceil(b / 2000)) for b in range(1, n + 1))}


def _replay(tmp_path, port: int, *lines: str) -> list[str]:
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(port, *lines))
    return [sys.executable, "-m", "cmsensord", "replay", str(capture(tmp_path, "--duration", "300")),
            "--config", str(cfg), "--out", str(tmp_path / "out"), "--publish"]


@pytest.mark.parametrize("lines", [(), ("handover_messages: 16",)], ids=["default", "small_handover"])
def test_an_unpaced_replay_delivers_every_message_before_it_exits(tmp_path, broker, lines):  # noqa: F811
    """With a hand-over queue of 16 messages the replay waits for room (it dropped 3,552 of an
    hour's 3,600 severity messages: 'the publisher fell behind')."""
    sub = Subscriber(broker.port)
    try:
        p = subprocess.run(_replay(tmp_path, broker.port, *lines), capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        n = len(expected(tmp_path / "out"))
        assert n > 800
        sending = [ln for ln in p.stderr.splitlines() if ln.startswith("mqtt: sending ")]
        assert len(sending) == 1 and 0 < (k := int(sending[0].split()[2].replace(",", ""))) <= n, p.stderr
        assert sending[0] in {SENDING.format(n=k, port=broker.port, pace=pace) for pace in _paces(k)}, p.stderr
        assert (f"  mqtt: {n} message(s) sent to 127.0.0.1:{broker.port} as client_id rig1, {n} acknowledged; 0 "
                f"left unacknowledged in {tmp_path / 'out' / 'mqtt-queue'}") in p.stderr.splitlines(), p.stderr
        assert "fell behind" not in p.stderr
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= n)
        assert sorted(set(seqs(sub))) == list(range(1, n + 1))
    finally:
        sub.close()


def test_without_a_broker_it_stops_waiting_after_10_s_and_keeps_the_queue(tmp_path):
    port = free_port()
    t0 = time.monotonic()
    p = subprocess.run(_replay(tmp_path, port), capture_output=True, text=True, timeout=120)
    waited = time.monotonic() - t0
    assert p.returncode == 0, p.stderr
    n = len(expected(tmp_path / "out"))
    lines = p.stderr.splitlines()
    link = [ln for ln in lines if ln.startswith("WARNING mqtt_link: ")]
    sending = [ln for ln in lines if ln.startswith("mqtt: sending ")]
    assert len(link) == 1 and len(sending) == 1, p.stderr
    # the link event is published too: said while it waits, it is the one message not yet offered;
    # a slow replay meets the first failed connect before its end and offers all n
    before = lines.index(link[0]) < lines.index(sending[0])
    k = n if before else n - 1
    assert sending[0] == SENDING.format(n=k, port=port, pace=NOT_CONNECTED.format(s=math.ceil(k / 2000))), p.stderr
    assert "mqtt: the broker acknowledged nothing for 10 s: stopped waiting" in lines, p.stderr
    assert any(ln.endswith(f"0 acknowledged; {n} left unacknowledged in {tmp_path / 'out' / 'mqtt-queue'}: the "
                           "next run publishing from this queue sends them first") for ln in lines), p.stderr
    assert 10 <= waited < 60


def test_a_full_queue_at_the_end_drops_the_oldest_and_counts_them(tmp_path):
    """No broker, ``queue_mb`` 0.1 MB (~250 messages): when the replay stops waiting, what it
    offered past the bound goes in as the daemon's does, the oldest dropped and counted, so
    dropped and left add up to every message (it threw 681 of 924 away, uncounted)."""
    out = tmp_path / "out"
    p = subprocess.run(_replay(tmp_path, free_port(), "queue_mb: 0.1"), capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    n = len(expected(out))
    said = re.search(r"  mqtt: 0 message\(s\) sent to .*, 0 acknowledged, (\d+) dropped; (\d+) left "
                     r"unacknowledged in ", p.stderr)
    assert said and int(said[1]) + int(said[2]) == n and 0 < int(said[2]) < 400, p.stderr
    assert (f"WARNING mqtt_queue: store-and-forward queue over 0.1 MB: dropped the {said[1]} oldest unsent "
            f"message(s) ({said[1]} in all)") in p.stderr.splitlines(), p.stderr


def test_ctrl_c_stops_waiting_and_the_run_ends_with_its_summary(tmp_path):
    port = free_port()
    proc = spawn(_replay(tmp_path, port), stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if line.startswith("mqtt: sending "):
            break
    proc.send_signal(signal.SIGINT)
    rest = proc.communicate(timeout=30)[1]
    assert proc.returncode == 130, "".join(seen) + rest
    assert "mqtt: stopped waiting (Ctrl-C)\n" in rest, rest
    assert "left unacknowledged in" in rest and "MCAP log:" in rest, rest
    assert "  interrupted (Ctrl-C) at 100% of the capture" in rest, rest


def test_a_broker_that_refuses_the_login_ends_the_wait_at_once_and_says_why(tmp_path):
    """It waited the 10 s for an acknowledgement and said why only after."""
    secured = free_port()
    pw = tmp_path / "broker.passwd"
    subprocess.run(["mosquitto_passwd", "-c", "-b", str(pw), "rig", "right"], check=True, capture_output=True)
    b = Broker(tmp_path / "broker", extra=f"listener {secured} 127.0.0.1\nallow_anonymous false\n"
               f"password_file {pw}\n").start()
    (tmp_path / "password").write_text("wrong\n")
    try:
        t0 = time.monotonic()
        p = subprocess.run(_replay(tmp_path, secured, "username: rig", f"password_file: {tmp_path / 'password'}"),
                           capture_output=True, text=True, timeout=120)
        waited = time.monotonic() - t0
    finally:
        b.stop()
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    refused = next(i for i, ln in enumerate(lines) if ln.startswith("ERROR mqtt_link: ") and "refused" in ln)
    assert lines.index("mqtt: the broker refused the connection: stopped waiting") > refused, p.stderr
    assert waited < 9, waited


def test_a_queue_that_cannot_be_written_does_not_hang_the_replay(tmp_path):
    """The hand-over queue small and the disk queue refusing writes (a file size limit): the
    replay neither hangs nor waits for room (the messages are held in memory), and its summary
    counts those the disk never took, lost with the run."""
    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (30_000, 30_000))

    out = tmp_path / "out"
    args = _replay(tmp_path, free_port(), "handover_messages: 16")
    p = subprocess.run(args, capture_output=True, text=True, timeout=120, preexec_fn=limit)
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stderr.splitlines() if " mqtt_queue: " in ln]
    assert len(said) == 1 and re.fullmatch(                 # a short write reads as a full disk
        rf"ERROR mqtt_queue: store-and-forward queue {re.escape(str(out / 'mqtt-queue'))}: cannot write \((No space "
        r"left on device|File too large)\); new messages are sent from memory, up to 4 MB kept until it takes them",
        said[0]), p.stderr
    said = re.search(r"  mqtt: 0 message\(s\) sent to .*, 0 acknowledged; (\d+) left unacknowledged in \S+ \((\d+) "
                     r"of them lost: held in memory, the disk refused them\): the next run", p.stderr)
    assert said and 0 < int(said[2]) < int(said[1]), p.stderr



@pytest.mark.parametrize("fsize", [None, 3_000], ids=["queue_bound", "memory_bound"])
def test_a_replay_waits_for_room_where_the_queue_s_bounds_would_drop(tmp_path, broker, fsize):  # noqa: F811
    """An unpaced replay offers its messages far faster than the broker acknowledges them: it
    waits while the queue is at ``queue_mb`` (0.1 MB: ~200 messages), or, the disk refusing
    writes (a file size limit under a segment's size), while the messages held in memory fill
    their bound (``queue_mb`` too: 0.02 MB), so the bounds drop none and the subscriber gets
    every seq (it dropped 2,496 of a 900-s capture's 2,736 at 0.1 MB)."""
    def limit():
        if fsize:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    sub = Subscriber(broker.port)
    try:
        args = _replay(tmp_path, broker.port, f"queue_mb: {0.02 if fsize else 0.1}")
        p = subprocess.run(args, capture_output=True, text=True, timeout=120, preexec_fn=limit)
        assert p.returncode == 0, p.stderr
        refused = [ln for ln in p.stderr.splitlines() if " mqtt_queue: " in ln and "cannot write" in ln]
        assert len(refused) == bool(fsize), p.stderr
        assert not fsize or refused[0].endswith("new messages are sent from memory, up to 0.02 MB kept until it "
                                                "takes them"), p.stderr
        assert "dropped" not in p.stderr and "fell behind" not in p.stderr, p.stderr
        said = re.search(r"  mqtt: (\d+) message\(s\) sent to .*, (\d+) acknowledged; 0 left unacknowledged", p.stderr)
        assert said and said[1] == said[2], p.stderr
        n = int(said[2])
        assert n > 800, n                               # several times what either bound holds
        assert sub.wait_for(lambda: len(set(seqs(sub))) >= n)
        assert sorted(set(seqs(sub))) == list(range(1, n + 1))
    finally:
        sub.close()
