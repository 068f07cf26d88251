"""Publishing to MQTT through the commands a user types, against a real Mosquitto broker
(tests/mosquitto.py): the topics and payloads, a broker outage, a kill -9 while the broker is
down, the queue's bound, TLS with a client certificate and a wrong password."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cmsensord.config.mqtt import RETAINED
from cmsensord.publish.disk_queue import DiskQueue
from cmsensord.publish.publisher import MAX_INFLIGHT, POLL_S
from cmsensord.publish.seq_lease import LEASE
from cmsensord.sinks.mcap_sink import iter_messages_lenient, read_messages
from mosquitto import Broker, Subscriber, free_port, needs_mosquitto, tls_broker
from processes import ENV, board_on_pty, cmsensord, spawn, start_daemon, stop

pytestmark = needs_mosquitto
PUBLISHED = ("severity", "indicators", "events", "diagnostics")
#: board seconds per wall second of the kill -9 test
SPEED = 2


def mqtt_yaml(port: int, *lines: str, publish=PUBLISHED) -> str:
    more = "".join(f"  {line}\n" for line in lines)
    return (f"mqtt:\n  host: 127.0.0.1\n  port: {port}\n  client_id: rig1\n  publish: [{', '.join(publish)}]\n"
            f"  reconnect_min_s: 0.2\n  reconnect_max_s: 1.0\n  resend_per_s: 2000\n{more}")


def simulate(tmp_path: Path, yaml: str, *args: str, duration: float = 60, speed: float = 20) -> list:
    cfg = tmp_path / "site.yaml"
    cfg.write_text("output:\n  status_line: false\n" + yaml)
    return [sys.executable, "-m", "cmsensord", "--simulate", "--publish", "--config", str(cfg), "--out",
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
        # the file is in log-time order (a late message is moved back in it), the broker gets the
        # messages as they were written: each topic's sequence is the same
        def per_topic(pairs):
            out: dict = {}
            for t, m in pairs:
                out.setdefault(t, []).append(m)
            return out
        assert per_topic((t, {k: v for k, v in m.items() if k != "seq"}) for t, m in got) == per_topic(want)
        status = [body for t, body, _ in sub.got if t == "cmsensord/rig1/status"]
        assert status[0] == b"online" and status[-1] == b"offline"
    finally:
        sub.close()


def test_a_broker_outage_loses_nothing_and_delivers_in_order(tmp_path, broker):
    sub = Subscriber(broker.port)
    daemon = spawn(simulate(tmp_path, mqtt_yaml(broker.port), duration=300),
                              stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        assert sub.wait_for(lambda: len(seqs(sub)) >= 200)     # a wrong rewind would repeat many
        broker.stop()
        time.sleep(3.0)                         # 60 s of the board's time at 20x
        broker.start()
        _, err = daemon.communicate(timeout=120)
        assert daemon.returncode == 0, err
        want = expected(tmp_path / "logs")
        assert sub.wait_for(lambda: set(seqs(sub)) >= set(range(1, len(want) + 1)))
        got = seqs(sub)
        assert first_occurrences(got) == list(range(1, len(want) + 1))    # in order, no gap
        # QoS 1 resends only the unacknowledged window; the connection also publishes again the
        # latest message of each retained topic the broker had acknowledged (README, `seq`). The
        # broker's own repeats to the subscriber (its retained store at the subscriber's
        # subscribing again after the restart, its unacknowledged deliveries) are not the daemon's.
        retained = {t for t, m in sub.messages() if "seq" in m and t.rsplit("/", 1)[-1] in RETAINED}
        forwarded = [m["seq"] for _, m in sub.messages(forwarded=True) if "seq" in m]
        assert len(forwarded) - len(want) <= MAX_INFLIGHT + len(retained), (len(forwarded) - len(want), retained)
        assert len(re.findall(r"mqtt_link: lost the broker 127\.0\.0\.1:\d+", err)) == 1, err
        assert "cannot connect" not in err      # the retries of one outage are one event
        assert len(re.findall(r"mqtt_link: connected to 127\.0\.0\.1", err)) == 2, err
    finally:
        daemon.kill()
        sub.close()


def test_messages_queued_while_the_broker_is_down_survive_a_kill_9(tmp_path):
    broker = Broker(tmp_path / "broker")           # not started: the broker is down
    yaml = mqtt_yaml(broker.port, f"queue_dir: {tmp_path / 'queue'}")
    with_board = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario",
                                   "degrading", "--speed", str(SPEED), "--duration", "600"],
                                  stdout=subprocess.PIPE, text=True, env=ENV)
    pty = with_board.stdout.readline().strip()
    daemon = start_daemon(tmp_path, pty, config=yaml)
    try:
        time.sleep(8.0)
        daemon.send_signal(signal.SIGKILL)
        daemon.wait(timeout=10)
    finally:
        with_board.terminate()
        with_board.wait(timeout=5)
    q = DiskQueue(tmp_path / "queue", max_bytes=64_000_000)
    kept = q.next_batch(1 << 20)
    queued, resume = len(kept), q.next_seq
    on_disk = {(r.topic, r.payload.rsplit(b',"seq":', 1)[0] + b"}") for r in kept}
    q.close()
    assert queued >= 20 and [r.seq for r in kept] == list(range(1, queued + 1))
    assert resume == LEASE + 1                  # the killed run leased 1..LEASE: none of them is used again
    # the queue lost at most the last second: it holds every message of the (flushed) MCAP log
    # but those of the last wall second (SPEED board seconds) before the kill
    (part,) = (tmp_path / "logs").glob("*.mcap.part")
    logged = [(t, s, data) for t, s, data in iter_messages_lenient(part)
              if t.strip("/").split("/")[-1] in PUBLISHED]
    missing = [s for t, s, data in logged if ("cmsensord/rig1" + t[3:], data) not in on_disk]
    assert len(logged) >= 20
    assert all(s >= logged[-1][1] - SPEED * 1e9 for s in missing), (len(missing), len(logged))
    broker.start()
    sub = Subscriber(broker.port)
    board2 = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--scenario",
                               "healthy", "--speed", "20", "--duration", "600"],
                              stdout=subprocess.PIPE, text=True, env=ENV)
    daemon = start_daemon(tmp_path, board2.stdout.readline().strip(), config=yaml)
    try:
        assert sub.wait_for(lambda: set(seqs(sub)) >= set(range(1, queued + 1)) | {resume})
        got = sub.messages()
        first = {m["seq"]: m for _, m in got if "seq" in m}
        assert first[1]["kind"] == "start"                      # the killed run's first event
        assert first[resume]["kind"] == "start"                 # the new run numbers above the lease
        assert first_occurrences([m["seq"] for _, m in got if "seq" in m])[:queued + 1] == \
            list(range(1, queued + 1)) + [resume]
    finally:
        daemon.terminate()
        daemon.communicate(timeout=20)
        board2.terminate()
        board2.wait(timeout=5)
        sub.close()
        broker.stop()


def test_a_kill_9_repeats_the_in_flight_and_what_was_acknowledged_since_the_position_was_written(
        tmp_path, broker):
    """README (``seq``): the restarted daemon sends again from the acknowledged position on disk,
    written every ``fsync_s`` (checked each POLL_S), so it repeats at most the MAX_INFLIGHT in
    flight plus what the broker acknowledged in the last fsync_s + POLL_S before the kill."""
    readme = " ".join((Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8").split())
    assert (f"Repeats after a kill -9: the restarted daemon sends from the acknowledged position on disk, "
            f"which it writes with each sync of the queue, every `fsync_s` (1 s, checked every {POLL_S:g} s), "
            f"so at most the {MAX_INFLIGHT} in flight plus the messages the broker acknowledged in the last "
            f"`fsync_s` + {POLL_S:g} s before the kill") in readme
    fsync_s = 2.0
    yaml = mqtt_yaml(broker.port, f"queue_dir: {tmp_path / 'queue'}", f"fsync_s: {fsync_s}")
    sub = Subscriber(broker.port)
    got: list[tuple[float, int]] = []             # (when received, seq)

    def stamped(client, userdata, msg) -> None:
        if msg.payload.startswith(b"{") and b'"seq":' in msg.payload:
            got.append((time.monotonic(), json.loads(msg.payload)["seq"]))

    sub.client.on_message = stamped
    board = ("--scenario", "healthy", "--channels", "4", "--speed", "10", "--duration", "600")
    try:
        with board_on_pty(*board) as pty:
            daemon = start_daemon(tmp_path, pty, config=yaml)
            time.sleep(4 * fsync_s)
            killed = time.monotonic()
            daemon.send_signal(signal.SIGKILL)
            daemon.wait(timeout=10)
        time.sleep(0.5)                             # what the broker had goes on to the subscriber
        before = list(got)
        first_run = {s for _, s in before}
        window = fsync_s + POLL_S + 0.3             # + the subscriber's lag behind the acknowledgement
        recent = sum(1 for when, _ in before if when > killed - window)
        assert len(first_run) > 200, len(first_run)                  # ~80 a second
        with board_on_pty(*board) as pty:
            daemon = start_daemon(tmp_path, pty, config=yaml)
            assert sub.wait_for(lambda: max(s for _, s in got) > max(first_run) + 50)
            stop(daemon)
        repeats = [s for _, s in got[len(before):] if s in first_run]
        assert len(repeats) <= MAX_INFLIGHT + recent, (len(repeats), recent)
        assert {s for _, s in got} >= set(range(1, max(first_run) + 1))     # and no gap
    finally:
        sub.close()


def test_the_queue_bound_drops_the_oldest_messages_with_an_event(tmp_path):
    down = free_port()                          # nothing listens there: the broker is down
    queue = tmp_path / "queue"
    p = subprocess.run(simulate(tmp_path, mqtt_yaml(down, "queue_mb: 0.01", f"queue_dir: {queue}")),
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert p.returncode == 0, p.stderr
    drops = [int(n) for n in re.findall(r"WARNING mqtt_queue: store-and-forward queue over 0\.01 MB: "
                                        r"dropped the (\d+) oldest unsent message\(s\)", p.stderr)]
    assert drops and sum(drops) > 0, p.stderr
    q = DiskQueue(queue, max_bytes=10_000)
    assert q.size_bytes <= 10_000 + 4096        # the bound and at most the open segment beyond it
    # nothing was sent: every message is either still queued or dropped (and counted by the
    # events; the event log may summarise a burst of them, and drops at the very end have no event)
    assert q.acked + q.depth == len(expected(tmp_path / "logs"))
    assert 0 < sum(drops) <= q.acked
    q.close()


def test_tls_with_a_client_certificate(tmp_path):
    broker, tls, certs = tls_broker(tmp_path, client_certificate=True)
    sub = Subscriber(broker.port)
    try:
        yaml = mqtt_yaml(tls, f"ca_file: {certs}/ca.pem", f"certfile: {certs}/client.pem",
                         f"keyfile: {certs}/client.key")
        p = subprocess.run(simulate(tmp_path, yaml), capture_output=True, text=True, env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        want = expected(tmp_path / "logs")
        assert sub.wait_for(lambda: len(seqs(sub)) >= len(want))
        assert first_occurrences(seqs(sub)) == list(range(1, len(want) + 1))
        assert f"mqtt_link: connected to 127.0.0.1:{tls} as rig1" in p.stderr
    finally:
        sub.close()
        broker.stop()


def test_a_wrong_password_is_one_clear_event_and_retries(tmp_path):
    secured = free_port()
    pw = tmp_path / "broker.passwd"
    subprocess.run(["mosquitto_passwd", "-c", "-b", str(pw), "rig", "right"], check=True, capture_output=True)
    broker = Broker(tmp_path / "broker", extra=(
        f"listener {secured} 127.0.0.1\nallow_anonymous false\npassword_file {pw}\n")).start()
    (tmp_path / "password").write_text("wrong\n")
    try:
        yaml = mqtt_yaml(secured, "username: rig", f"password_file: {tmp_path / 'password'}")
        p = subprocess.run(simulate(tmp_path, yaml, duration=60, speed=10), capture_output=True, text=True,
                           env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        link = [line for line in p.stderr.splitlines() if "mqtt_link:" in line]
        assert len(link) == 1, p.stderr
        assert re.fullmatch(rf"ERROR mqtt_link: broker 127\.0\.0\.1:{secured} refused the connection: "
                            r"Not authorized; retrying with back-off up to 1 s, \d+ message\(s\) queued",
                            link[0]), link
        assert broker.log().count("not authorised") >= 3     # it kept trying
    finally:
        broker.stop()


@pytest.mark.parametrize(("yaml", "line"), [
    ("mqtt:\n  host: h\n  password: secret\n",
     "mqtt.password: unknown key 'password' (did you mean 'password_file'?)"),
    ("mqtt:\n  host: h\n  qos: 2\n", "mqtt.qos: must be one of 0, 1 (got 2)"),
    ("mqtt:\n  host: h\n  publish: [severity, akf]\n",
     "mqtt.publish: unknown kind 'akf'; choose from severity, indicators, alarms, events, diagnostics, "
     "orders, vibration_estimate (got 'akf')"),
    ("mqtt:\n  host: h\n  username: u\n  password_file: /nonexistent/pw\n",
     "mqtt.password_file: cannot read: No such file or directory (got '/nonexistent/pw')"),
])
def test_mqtt_config_errors_are_one_line(tmp_path, yaml, line):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml)
    p = cmsensord("--config", str(cfg))
    assert p.returncode == 78, p.stderr
    assert p.stderr.strip().splitlines() == [f"cmsensord: configuration error: {cfg}: {line}"]


def test_mqtt_without_paho_is_a_config_error_and_without_mqtt_paho_is_not_imported(tmp_path):
    fake = tmp_path / "site" / "paho"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("")      # a paho package without paho.mqtt
    cfg = tmp_path / "c.yaml"
    cfg.write_text("mqtt:\n  host: h\n")
    env = dict(ENV, PYTHONPATH=f"{tmp_path / 'site'}{os.pathsep}{ENV['PYTHONPATH']}")
    p = subprocess.run([sys.executable, "-m", "cmsensord", "--config", str(cfg)], capture_output=True,
                       text=True, env=env, timeout=60)
    assert p.returncode == 78
    assert p.stderr.strip() == (f"cmsensord: configuration error: {cfg}: mqtt: publishing needs paho-mqtt: "
                                "pip install 'cmsensord[mqtt]'")
    p = subprocess.run(simulate(tmp_path, "", duration=4), capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 0, p.stderr
    check = ("import sys, cmsensord.cli, cmsensord.service.live, cmsensord.service.sink; "
             "print([m for m in sys.modules if m.startswith('paho') or m == 'ssl'])")   # ssl: 2 MB of RSS
    assert subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                          env=ENV).stdout.strip() == "[]"


#: two rules on the simulated motor: an alert at once, a danger while the severity is over 0.5
FIRING = ("alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 0.000001}\n"
          "    - {name: sev, indicator: severity_index, danger: 0.5}\n")


def test_status_line_diagnostics_and_home_assistant_discovery(tmp_path, broker):
    sub = Subscriber(broker.port)
    try:
        yaml = mqtt_yaml(broker.port, "discovery: true", publish=(*PUBLISHED, "alarms")) + FIRING
        cmd = simulate(tmp_path, yaml, duration=30)
        (tmp_path / "site.yaml").write_text((tmp_path / "site.yaml").read_text().replace(
            "status_line: false", "status_line: true"))
        p = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        assert re.search(r"\| mqtt connected q \d+$", p.stderr, re.M), p.stderr
        diags = [m for t, m in expected(tmp_path / "logs") if t.endswith("/diagnostics")]
        assert diags and diags[-1]["mqtt"]["state"] == "connected" and diags[-1]["mqtt"]["dropped"] == 0
        topic = "homeassistant/sensor/rig1_ch0_severity/config"
        assert sub.wait_for(lambda: any(t == topic for t, _, _ in sub.got))
        config = next(json.loads(body) for t, body, _ in sub.got if t == topic)
        assert (config["state_topic"], config["value_template"], config["availability_topic"]) == (
            "cmsensord/rig1/ch0/severity", "{{ value_json.severity_index }}", "cmsensord/rig1/status")
        topic = "homeassistant/sensor/rig1_ch0_worst_alarm/config"
        assert sub.wait_for(lambda: any(t == topic for t, _, _ in sub.got))
        config = next(json.loads(body) for t, body, _ in sub.got if t == topic)
        assert (config["state_topic"], config["value_template"], config["options"]) == (
            "cmsensord/rig1/ch0/worst_alarm", "{{ value_json.level }}", ["normal", "alert", "danger"])
        # ch0's worst alarm at each change of the logged tables (one channel: the table's worst)
        tables = [m for t, m in expected(tmp_path / "logs", ("alarms",))]
        worst = [(t["worst"], t.get("worst_alarm")) for t in tables]
        changed = [t for i, t in enumerate(tables) if i == 0 or worst[i] != worst[i - 1]]
        changes = [(t["worst"], t.get("worst_alarm"), t["timestamp"]) for t in changed]
        assert [c[:2] for c in changes[:2]] == [("alert", "rms/ch0"), ("danger", "sev/ch0")]
        assert sub.wait_for(lambda: len(sub.messages("/ch0/worst_alarm")) >= len(changes))
        states = [m for _, m in sub.messages("/ch0/worst_alarm")]
        assert [(m["level"], m.get("alarm"), m["timestamp"]) for m in states] == changes
        assert {k for m in states for k in m} == {"timestamp", "seq", "level", "alarm"}
    finally:
        sub.close()
    # a dashboard that subscribes later gets ch0's worst alarm of the last table, retained
    late = Subscriber(broker.port, "cmsensord/rig1/ch0/worst_alarm", client_id="late")
    try:
        assert late.wait_for(lambda: late.got)
        topic, body, retained = late.got[0]
        state = json.loads(body)
        assert retained and (state["level"], state.get("alarm"), state["timestamp"]) == changes[-1]
    finally:
        late.close()
