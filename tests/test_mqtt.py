"""Publishing to MQTT through the commands a user types, against a real Mosquitto broker
(tests/mosquitto.py): the topics and payloads, a broker outage, a kill -9 while the broker is
down, the queue's bound, TLS with a client certificate and a wrong password."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cmsensord.publish.disk_queue import DiskQueue
from cmsensord.sinks.mcap_sink import read_messages
from mosquitto import Broker, Subscriber, free_port, needs_mosquitto
from processes import ENV, cmsensord, start_daemon

pytestmark = needs_mosquitto
PUBLISHED = ("severity", "indicators", "events", "diagnostics")


def mqtt_yaml(port: int, *lines: str, publish=PUBLISHED) -> str:
    return ("mqtt:\n  host: 127.0.0.1\n  port: %d\n  client_id: rig1\n  publish: [%s]\n"
            "  reconnect_min_s: 0.2\n  reconnect_max_s: 1.0\n  resend_per_s: 2000\n%s"
            % (port, ", ".join(publish), "".join(f"  {line}\n" for line in lines)))


def simulate(tmp_path: Path, yaml: str, *args: str, duration: float = 60, speed: float = 20) -> list:
    cfg = tmp_path / "site.yaml"
    cfg.write_text("output:\n  status_line: false\n" + yaml)
    return [sys.executable, "-m", "cmsensord", "--simulate", "--config", str(cfg), "--out",
            str(tmp_path / "logs"), "--duration", str(duration), "--speed", str(speed), *args]


def expected(logs: Path, kinds=PUBLISHED) -> list[tuple[str, dict]]:
    """(MQTT topic, message) of every published MCAP message, in the order of the files."""
    out = []
    for path in sorted(logs.glob("*.mcap")):
        for topic, _, msg in read_messages(path):
            parts = topic.strip("/").split("/")
            if parts[-1] in kinds:
                out.append(("cmsensord/rig1/" + "/".join(parts[1:]), msg))
    return out


def seqs(sub: Subscriber) -> list[int]:
    return [m["seq"] for t, m in sub.messages() if "seq" in m]


def first_occurrences(values: list[int]) -> list[int]:
    seen: set[int] = set()
    return [v for v in values if not (v in seen or seen.add(v))]


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path / "broker").start()
    yield b
    b.stop()


def test_every_configured_topic_arrives_with_the_payload_of_its_mcap_message(tmp_path, broker):
    sub = Subscriber(broker.port)
    try:
        p = subprocess.run(simulate(tmp_path, mqtt_yaml(broker.port)), capture_output=True, text=True,
                           env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        want = expected(tmp_path / "logs")
        assert {t.rsplit("/", 1)[-1] for t, _ in want} == set(PUBLISHED)
        assert sub.wait_for(lambda: len(seqs(sub)) >= len(want)), (len(seqs(sub)), len(want))
        got = [(t, m) for t, m in sub.messages() if "seq" in m]
        assert [m["seq"] for _, m in got] == list(range(1, len(want) + 1))
        assert [(t, {k: v for k, v in m.items() if k != "seq"}) for t, m in got] == want
        status = [body for t, body, _ in sub.got if t == "cmsensord/rig1/status"]
        assert status[0] == b"online" and status[-1] == b"offline"
    finally:
        sub.close()


def test_a_broker_outage_loses_nothing_and_delivers_in_order(tmp_path, broker):
    sub = Subscriber(broker.port)
    daemon = subprocess.Popen(simulate(tmp_path, mqtt_yaml(broker.port), duration=300),
                              stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        assert sub.wait_for(lambda: len(seqs(sub)) >= 20)
        broker.stop()
        time.sleep(3.0)                         # 60 s of the board's time at 20x
        broker.start()
        _, err = daemon.communicate(timeout=120)
        assert daemon.returncode == 0, err
        want = expected(tmp_path / "logs")
        assert sub.wait_for(lambda: set(seqs(sub)) >= set(range(1, len(want) + 1)))
        got = seqs(sub)
        assert first_occurrences(got) == list(range(1, len(want) + 1))    # in order, no gap
        assert len(got) - len(want) <= 20       # QoS 1 resends only the unacknowledged window
        assert len(re.findall(r"mqtt_link: lost the broker 127\.0\.0\.1:\d+", err)) == 1, err
        assert len(re.findall(r"mqtt_link: connected to 127\.0\.0\.1", err)) == 2, err
    finally:
        daemon.kill()
        sub.close()


def test_messages_queued_while_the_broker_is_down_survive_a_kill_9(tmp_path):
    broker = Broker(tmp_path / "broker")           # not started: the broker is down
    yaml = mqtt_yaml(broker.port, f"queue_dir: {tmp_path / 'queue'}")
    with_board = subprocess.Popen([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario",
                                   "degrading", "--speed", "20", "--duration", "600"],
                                  stdout=subprocess.PIPE, text=True, env=ENV)
    pty = with_board.stdout.readline().strip()
    daemon = start_daemon(tmp_path, pty, config=yaml)
    try:
        time.sleep(5.0)
        daemon.send_signal(signal.SIGKILL)
        daemon.wait(timeout=10)
    finally:
        with_board.terminate()
        with_board.wait(timeout=5)
    q = DiskQueue(tmp_path / "queue", max_bytes=64_000_000)
    queued = q.next_seq - 1
    q.close()
    assert queued >= 20
    broker.start()
    sub = Subscriber(broker.port)
    board2 = subprocess.Popen([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario",
                               "healthy", "--speed", "20", "--duration", "600"],
                              stdout=subprocess.PIPE, text=True, env=ENV)
    daemon = start_daemon(tmp_path, board2.stdout.readline().strip(), config=yaml)
    try:
        assert sub.wait_for(lambda: set(seqs(sub)) >= set(range(1, queued + 2)))
        got = sub.messages()
        first = {m["seq"]: m for _, m in got if "seq" in m}
        assert first[1]["kind"] == "start"                      # the killed run's first event
        assert first[queued + 1]["kind"] == "start"             # the new run goes on numbering
        assert first_occurrences([m["seq"] for _, m in got if "seq" in m])[:queued + 1] == \
            list(range(1, queued + 2))
    finally:
        daemon.terminate()
        daemon.communicate(timeout=20)
        board2.terminate()
        board2.wait(timeout=5)
        sub.close()
        broker.stop()
