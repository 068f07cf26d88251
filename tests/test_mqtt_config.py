"""The ``mqtt`` section's errors a user meets at start, through ``cmsensord --config FILE``: a
host written as a URL. Each is one line naming the key, exit status 78, before any
connection is tried."""

from __future__ import annotations

from pathlib import Path

import pytest

from processes import cmsensord

EXIT_CONFIG = 78


def config_error(tmp_path: Path, mqtt: str, host: str = "127.0.0.1") -> str:
    """The one stderr line of ``cmsensord --config`` with this mqtt section (exit 78), less its
    ``cmsensord: configuration error: FILE: `` head."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"output:\n  dir: {tmp_path / 'logs'}\nmqtt:\n  host: {host}\n{mqtt}")
    p = cmsensord("--config", str(cfg), timeout=30)   # a config that passes starts the daemon
    assert p.returncode == EXIT_CONFIG, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    head = f"cmsensord: configuration error: {cfg}: "
    assert lines[0].startswith(head), lines
    return lines[0][len(head):]


@pytest.mark.parametrize(("host", "line"), [
    ("mqtt://broker:1883", "mqtt.host: give the host name alone (broker), the port as mqtt.port: 1883 "
                           "(got 'mqtt://broker:1883')"),
    ("mqtts://broker.plant.local", "mqtt.host: give the host name alone (broker.plant.local); mqtts:// means "
                                   "TLS: set mqtt.ca_file to the broker's CA certificate and mqtt.port (8883 is "
                                   "the usual TLS port) (got 'mqtts://broker.plant.local')"),
    ("broker:8883", "mqtt.host: give the host name alone (broker), the port as mqtt.port: 8883 "
                    "(got 'broker:8883')"),
    ("tcp://10.0.0.5/mqtt", "mqtt.host: give the host name alone (10.0.0.5) (got 'tcp://10.0.0.5/mqtt')"),
])
def test_a_host_with_a_scheme_port_or_path_says_what_to_write(tmp_path, host, line):
    assert config_error(tmp_path, "", host=host) == line


def test_an_ipv6_address_is_a_host(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("mqtt:\n  host: '::1'\n  ca_file: /nonexistent/ca.pem\n")
    p = cmsensord("--config", str(cfg))      # the host passes: the next error is the missing file
    assert p.returncode == EXIT_CONFIG
    assert "mqtt.ca_file: cannot read: No such file or directory" in p.stderr, p.stderr
