"""Which runs publish, and what they tell, against a real Mosquitto broker (tests/mosquitto.py):
``replay`` and ``vkf`` ignore the ``mqtt`` section unless ``--publish`` is given."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mosquitto import Broker, Subscriber, needs_mosquitto
from processes import ENV, cmsensord
from test_mqtt import mqtt_yaml, seqs

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
