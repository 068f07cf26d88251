"""Which runs publish, what they tell and what a broker restart keeps, against a real Mosquitto
broker (tests/mosquitto.py): ``replay`` ignores the ``mqtt`` section unless ``--publish`` is given;
the retained state is published again at each connection."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cmsensord.publish.disk_queue import DiskQueue
from mosquitto import Broker, Subscriber, free_port, needs_mosquitto
from processes import ENV, board_then_daemon, cmsensord, spawn
from test_mqtt import expected, mqtt_yaml, seqs, simulate

pytestmark = needs_mosquitto


@pytest.fixture
def broker(tmp_path):
    b = Broker(tmp_path / "broker").start()
    yield b
    b.stop()


def capture(tmp_path: Path, *args: str) -> Path:
    """A capture file of the simulated board (``python -m firmware_sim --out``)."""
    path = tmp_path / "cap.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "faulty", "--duration", "20",
                    *args, "--out", str(path)], check=True, capture_output=True, env=ENV, timeout=60)
    return path


def test_replay_ignores_the_mqtt_section_unless_told_to_publish(tmp_path, broker):
    cap = capture(tmp_path)
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(broker.port))
    sub = Subscriber(broker.port)
    try:
        p = cmsensord("-v", "replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "quiet"))
        assert p.returncode == 0, p.stderr
        assert ("INFO mqtt: the mqtt section is ignored: replay does not publish (it would publish as "
                "client_id rig1 under cmsensord/rig1/, the live daemon's); give --publish to publish it"
                ) in p.stderr.splitlines(), p.stderr
        assert not (tmp_path / "quiet" / "mqtt-queue").exists()
        assert "rig1" not in broker.log()           # it never connected: a live rig1 is not kicked off
        p = cmsensord("-v", "replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "published"),
                      "--publish", "--speed", "10")       # paced: 2 s, time to connect
        assert p.returncode == 0, p.stderr
        assert f"INFO mqtt: replay publishes to 127.0.0.1:{broker.port} as client_id rig1 under " \
               "cmsensord/rig1/" in p.stderr.splitlines(), p.stderr
        assert sub.wait_for(lambda: seqs(sub)[:1] == [1])
    finally:
        sub.close()


#: an alert at once, a latched danger once the severity is over 0.5: the table then stays put
LATCHED = ("alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 0.000001}\n"
           "    - {name: sev, indicator: severity_index, danger: 0.5, latch: true}\n")


def test_retained_state_is_published_again_after_a_broker_restart_without_persistence(tmp_path):
    broker = Broker(tmp_path / "broker", persistence=False).start()
    sub = Subscriber(broker.port)
    yaml = mqtt_yaml(broker.port, "discovery: true", publish=("severity", "alarms", "events")) + LATCHED
    daemon = spawn(simulate(tmp_path, yaml, duration=400, speed=20), stderr=subprocess.PIPE, text=True)
    try:
        assert sub.wait_for(lambda: any(m["level"] == "danger" for _, m in sub.messages("/ch0/worst_alarm")))
        sub.close()
        time.sleep(1.0)                             # the danger's table acknowledged
        broker.stop()                               # it forgets every retained message
        broker.start()
        probe = Subscriber(broker.port, "cmsensord/rig1/status", client_id="probe")
        assert probe.wait_for(lambda: (probe.got[-1:] or [("", b"")])[0][1] == b"online", timeout=20)
        probe.close()
        time.sleep(0.5)                             # the daemon re-published in the same breath
        late = Subscriber(broker.port, "cmsensord/rig1/+/worst_alarm", client_id="late")
        tables = Subscriber(broker.port, "cmsensord/rig1/alarms", client_id="late-tables")
        try:
            assert late.wait_for(lambda: late.got, timeout=5)
            topic, body, retained = late.got[0]
            assert (topic, json.loads(body)["level"], retained) == ("cmsensord/rig1/ch0/worst_alarm", "danger", True)
            assert tables.wait_for(lambda: tables.got, timeout=5)
            topic, body, retained = tables.got[0]
            assert retained and json.loads(body)["worst"] == "danger"
        finally:
            late.close()
            tables.close()
    finally:
        daemon.kill()
        daemon.communicate()
        broker.stop()


def test_discovery_and_worst_alarm_cover_the_channels_the_board_sends(tmp_path, broker):
    sub = Subscriber(broker.port)
    try:
        yaml = mqtt_yaml(broker.port, "discovery: true", publish=("severity", "alarms")) + LATCHED
        board_then_daemon(tmp_path, "--scenario", "faulty", "--channels", "3", "--speed", "20",
                          "--duration", "20", config=yaml)       # no channels: list, the board's 3
        names = [f"homeassistant/sensor/rig1_{ch}_{what}/config" for ch in ("ch0", "ch1", "ch2")
                 for what in ("severity", "worst_alarm")]
        assert sub.wait_for(lambda: set(names) <= {t for t, _, _ in sub.got}), sorted({t for t, _, _ in sub.got})
        config = next(json.loads(body) for t, body, _ in sub.got if t == names[-1])
        assert config["state_topic"] == "cmsensord/rig1/ch2/worst_alarm"
        assert sub.wait_for(lambda: any(m["level"] == "alert" for _, m in sub.messages("/ch2/worst_alarm")))
        assert sub.messages("/ch2/worst_alarm")[0][1]["level"] == "normal"   # the first table's
    finally:
        sub.close()


def test_without_alarm_rules_no_worst_alarm_is_announced_or_published(tmp_path, broker):
    sub = Subscriber(broker.port)
    try:
        yaml = mqtt_yaml(broker.port, "discovery: true", publish=("severity", "alarms"))
        p = subprocess.run(simulate(tmp_path, yaml, duration=20), capture_output=True, text=True, env=ENV,
                           timeout=120)
        assert p.returncode == 0, p.stderr
        severity = "homeassistant/sensor/rig1_ch0_severity/config"
        assert sub.wait_for(lambda: any(t == severity for t, _, _ in sub.got))
        assert sub.wait_for(lambda: sub.messages("/ch0/severity"))
        assert not [t for t, body, _ in sub.got if "worst_alarm" in t and body]   # it would stay "unknown"
    finally:
        sub.close()


def retain(port: int, topic: str, body: str) -> None:
    """``body`` retained at ``topic`` on the broker, as an earlier run left it."""
    import paho.mqtt.client as mqtt

    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="earlier-run")
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        client.publish(topic, body, qos=1, retain=True).wait_for_publish(timeout=10)
    finally:
        client.loop_stop()
        client.disconnect()


def test_discovery_announces_only_the_sensors_whose_state_is_published(tmp_path, broker):
    """``publish: [alarms, events]``: no severity sensor (nothing is ever sent on its state topic,
    so it would stay "unknown"), and the one an earlier configuration announced is removed from
    the broker; the worst alarm sensor of each channel is announced and gets its state."""
    earlier = "homeassistant/sensor/rig1_ch0_severity/config"
    retain(broker.port, earlier, json.dumps({"name": "ch0 severity", "state_topic": "cmsensord/rig1/ch0/severity"}))
    yaml = mqtt_yaml(broker.port, "discovery: true", publish=("alarms", "events")) + LATCHED
    p = subprocess.run(simulate(tmp_path, yaml, duration=20), capture_output=True, text=True, env=ENV,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    late = Subscriber(broker.port, "homeassistant/#", client_id="late")     # what the broker keeps
    states = Subscriber(broker.port, "cmsensord/rig1/#", client_id="late-states")
    try:
        assert late.wait_for(lambda: late.got, timeout=5)
        time.sleep(0.5)                             # every retained message delivered
        kept = {t: json.loads(body) for t, body, retained in late.got if retained}
        assert kept and all(t.endswith("_worst_alarm/config") for t in kept), sorted(kept)
        assert earlier not in kept
        assert states.wait_for(lambda: {c["state_topic"] for c in kept.values()} <= {t for t, _, _ in states.got})
        assert not [t for t, _, _ in states.got if t.endswith("/severity")]
    finally:
        late.close()
        states.close()


def test_live_messages_are_not_held_to_the_backlog_rate_and_the_summary_counts_them(tmp_path, broker):
    sub = Subscriber(broker.port)
    try:
        yaml = mqtt_yaml(broker.port).replace("resend_per_s: 2000", "resend_per_s: 5")
        p = subprocess.run(simulate(tmp_path, yaml), capture_output=True, text=True, env=ENV, timeout=120)
        assert p.returncode == 0, p.stderr
        n = len(expected(tmp_path / "logs"))           # ~80 a second at 20x, 3 s
        assert n > 100
        assert sub.wait_for(lambda: len(seqs(sub)) >= n, timeout=10)
        assert f"  mqtt: {n} message(s) sent to 127.0.0.1:{broker.port} as client_id rig1, {n} acknowledged; " \
               f"0 left unacknowledged in {tmp_path / 'logs' / 'mqtt-queue'}" in p.stderr.splitlines(), p.stderr
    finally:
        sub.close()


def test_the_exit_summary_says_what_is_left_for_the_next_run(tmp_path):
    down = free_port()                                  # nothing listens there: the broker is down
    p = subprocess.run(simulate(tmp_path, mqtt_yaml(down), duration=20), capture_output=True, text=True,
                       env=ENV, timeout=120)
    assert p.returncode == 0, p.stderr
    queue = tmp_path / "logs" / "mqtt-queue"
    q = DiskQueue(queue, max_bytes=64_000_000)
    left = q.depth
    q.close()
    assert left == len(expected(tmp_path / "logs")) > 0
    assert f"  mqtt: 0 message(s) sent to 127.0.0.1:{down} as client_id rig1, 0 acknowledged; {left} left " \
           f"unacknowledged in {queue}: the next run publishing from this queue sends them first" \
           in p.stderr.splitlines(), p.stderr


def test_a_simulated_board_with_the_site_config_publishes_only_when_told(tmp_path, broker):
    """``--simulate --config site.yaml`` (a test of the set-up beside the service) published its
    simulated alarms under the live daemon's client id and retained topics: now not without
    ``--publish``, and one warning says so."""
    sub = Subscriber(broker.port)
    try:
        args = [a for a in simulate(tmp_path, mqtt_yaml(broker.port), duration=10) if a != "--publish"]
        p = subprocess.run(args, capture_output=True, text=True, env=ENV, timeout=120)
        time.sleep(1.0)
    finally:
        sub.close()
    assert p.returncode == 0, p.stderr
    assert "WARNING mqtt: the mqtt section is ignored: a simulated board would publish as client_id rig1 under " \
           "cmsensord/rig1/, the live daemon's (its retained alarms, its dashboards); give --publish to publish it" \
           in p.stderr, p.stderr
    assert [t for t, _, _ in sub.got if t.startswith("cmsensord/rig1/")] == []
