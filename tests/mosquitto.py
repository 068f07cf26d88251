"""A real Mosquitto broker for the MQTT tests, on 127.0.0.1 and a free port, and a subscriber.

The broker is Debian's ``mosquitto`` (``.ci/run`` installs it when missing); it keeps its
sessions on disk across a restart (``persistence``), so a subscriber with a persistent session
misses nothing while the broker is down. :func:`make_certificates` makes a test CA and
certificates with ``openssl``.
"""

from __future__ import annotations

import getpass
import json
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

MOSQUITTO = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None)
needs_mosquitto = pytest.mark.skipif(MOSQUITTO is None, reason="mosquitto is not installed "
                                     "(.ci/run installs Debian's mosquitto package when it is missing)")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    """``mosquitto -c`` with a plain listener on :attr:`port` (for the subscriber) and ``extra``
    configuration lines (more listeners, TLS, passwords); ``persistence``: False, a restart
    forgets every retained message and session."""

    def __init__(self, work: Path, extra: str = "", anonymous: bool = True, persistence: bool = True) -> None:
        self.work, self.port = work, free_port()
        work.mkdir(parents=True, exist_ok=True)
        self.conf = work / "mosquitto.conf"
        # run as the test's user: as root, mosquitto would drop to "mosquitto" and not read tmp_path
        self.conf.write_text(f"user {getpass.getuser()}\nper_listener_settings true\nlistener {self.port} 127.0.0.1\n"
                             f"allow_anonymous true\n{extra}"
                             f"persistence {str(persistence).lower()}\npersistence_location {work}/\n"
                             f"log_dest file {work}/mosquitto.log\nlog_type all\n")
        self.proc: subprocess.Popen | None = None

    def start(self) -> Broker:
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return self
            except OSError:
                assert self.proc.poll() is None, self.proc.stderr.read()
                time.sleep(0.05)
        raise AssertionError("mosquitto did not start")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=10)
        self.proc = None

    def log(self) -> str:
        path = self.work / "mosquitto.log"
        return path.read_text(errors="replace") if path.exists() else ""


class Subscriber:
    """A paho client subscribed to ``topic`` (QoS 1, persistent session) that reconnects by itself:
    :attr:`got` is every (topic, payload bytes, retained) received, in order; :attr:`again`, in
    step with it, whether the broker sent that message again itself: from its retained store as
    the subscriber (re)subscribed, or as a DUP of its own unacknowledged delivery."""

    def __init__(self, port: int, topic: str = "#", client_id: str = "test-subscriber") -> None:
        import paho.mqtt.client as mqtt

        self.got: list[tuple[str, bytes, bool]] = []
        self.again: list[bool] = []
        self.lock = threading.Lock()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id,
                                  clean_session=False)
        self.client.reconnect_delay_set(0.1, 0.3)
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(topic, qos=1)
        self.client.on_message = self._message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _message(self, client, userdata, msg) -> None:
        with self.lock:
            self.got.append((msg.topic, msg.payload, bool(msg.retain)))
            self.again.append(bool(msg.retain) or bool(msg.dup))

    def messages(self, suffix: str = "", forwarded: bool = False) -> list[tuple[str, dict]]:
        """(topic, decoded JSON) of the JSON messages received on topics ending in ``suffix``;
        ``forwarded``: only those the broker forwarded as a publisher sent them (not :attr:`again`)."""
        with self.lock:
            got = [g for g, again in zip(self.got, self.again) if not (forwarded and again)]
        out = []
        for topic, body, _ in got:
            if topic.endswith(suffix) and body.startswith(b"{"):
                out.append((topic, json.loads(body)))
        return out

    def wait_for(self, test, timeout: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if test():
                return True
            time.sleep(0.1)
        return test()

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True)


def make_certificates(d: Path) -> None:
    """A test CA, a server certificate for 127.0.0.1 and a client certificate, both signed by it."""
    d.mkdir()
    _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem",
             "-days", "2", "-subj", "/CN=cmsensord test CA", cwd=d)
    (d / "san.ext").write_text("subjectAltName=IP:127.0.0.1\n")
    for name, ext in (("server", ["-extfile", "san.ext"]), ("client", [])):
        _openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key", "-out", f"{name}.csr",
                 "-subj", f"/CN={'127.0.0.1' if name == 'server' else 'rig1'}", cwd=d)
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
                 "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", *ext, cwd=d)


def tls_broker(work: Path, *, client_certificate: bool = False) -> tuple[Broker, int, Path]:
    """A started broker with a TLS listener on 127.0.0.1 (certificates made in ``work``/certs;
    ``client_certificate``: the listener requires one): (the broker, the TLS port, the certs)."""
    certs = work / "certs"
    make_certificates(certs)
    tls = free_port()
    broker = Broker(work / "broker", extra=(
        f"listener {tls} 127.0.0.1\nallow_anonymous true\ncafile {certs}/ca.pem\n"
        f"certfile {certs}/server.pem\nkeyfile {certs}/server.key\n"
        + ("require_certificate true\n" if client_certificate else ""))).start()
    return broker, tls, certs
