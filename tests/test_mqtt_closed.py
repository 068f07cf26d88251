"""A connection the broker closes without a reason (paho's "Unspecified error"), against a real
Mosquitto broker (tests/mosquitto.py): the daemon's mqtt_link line names the likely causes,
another client with the same client_id, plain MQTT spoken to a TLS port."""

from __future__ import annotations

import re
import subprocess

from mosquitto import Broker, Subscriber, needs_mosquitto, tls_broker
from processes import ENV, spawn
from test_mqtt import mqtt_yaml, simulate

pytestmark = needs_mosquitto


def link_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "mqtt_link:" in line]


def test_another_client_with_the_same_client_id_is_named_as_the_likely_cause(tmp_path):
    import paho.mqtt.client as mqtt

    broker = Broker(tmp_path / "broker").start()
    watch = Subscriber(broker.port, "cmsensord/rig1/status", client_id="watch")
    try:
        daemon = spawn(simulate(tmp_path, mqtt_yaml(broker.port), duration=60, speed=5),
                       stderr=subprocess.PIPE, text=True)
        assert watch.wait_for(lambda: (b"online" in [body for _, body, _ in watch.got])), "never connected"
        intruder = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="rig1")
        intruder.connect("127.0.0.1", broker.port)
        for _ in range(5):
            intruder.loop(0.1)
        intruder.disconnect()
        _, err = daemon.communicate(timeout=120)
        assert daemon.returncode == 0, err
    finally:
        watch.close()
        broker.stop()
    lost = [line for line in link_lines(err) if "lost the broker" in line]
    assert len(lost) == 1, err
    assert re.fullmatch(rf"WARNING mqtt_link: lost the broker 127\.0\.0\.1:{broker.port}: Unspecified error "
                        r"\(the broker closed the connection: another client using client_id rig1\? the broker "
                        r"stopping\?\); retrying with back-off up to 1 s, \d+ message\(s\) queued", lost[0]), lost


def test_plain_mqtt_to_a_tls_port_is_named_as_the_likely_cause(tmp_path):
    broker, tls, _ = tls_broker(tmp_path)
    try:
        p = subprocess.run(simulate(tmp_path, mqtt_yaml(tls), duration=30, speed=10), capture_output=True,
                           text=True, timeout=120, env=ENV)
    finally:
        broker.stop()
    assert p.returncode == 0, p.stderr
    assert re.fullmatch(rf"WARNING mqtt_link: cannot connect to 127\.0\.0\.1:{tls}: Unspecified error \(the "
                        r"broker closed the connection: a TLS port without mqtt\.ca_file\? the broker's log says "
                        r"why\); retrying with back-off up to 1 s, \d+ message\(s\) queued",
                        link_lines(p.stderr)[0]), p.stderr
