"""The ``mqtt`` section's errors a user meets at start, through ``cmsensord --config FILE``: a
host written as a URL, and TLS files that are not what their setting is for. Each is one
line naming the key and the file, exit status 78, before any connection is tried."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from mosquitto import make_certificates
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


@pytest.fixture(scope="module")
def certs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("tls") / "certs"
    make_certificates(d)
    subprocess.run(["openssl", "x509", "-in", d / "ca.pem", "-outform", "der", "-out", d / "ca.der"], check=True)
    subprocess.run(["openssl", "pkey", "-in", d / "client.key", "-aes256", "-passout", "pass:secret",
                    "-out", d / "locked.key"], check=True)
    return d


def test_a_ca_file_holding_a_key_is_a_configuration_error(tmp_path, certs):
    assert config_error(tmp_path, f"  ca_file: {certs}/ca.key\n") == (
        f"mqtt.ca_file: {certs}/ca.key: no certificate in it (it holds PRIVATE KEY): give the broker's CA "
        "certificate, PEM (-----BEGIN CERTIFICATE-----)")


def test_a_ca_file_that_is_not_pem_is_a_configuration_error(tmp_path, certs):
    assert config_error(tmp_path, f"  ca_file: {certs}/ca.der\n") == (
        f"mqtt.ca_file: {certs}/ca.der: no certificate in it (it is not PEM (DER? openssl x509 -inform der "
        "converts it)): give the broker's CA certificate, PEM (-----BEGIN CERTIFICATE-----)")


def test_a_key_that_is_not_the_certificates_is_a_configuration_error(tmp_path, certs):
    mqtt = f"  ca_file: {certs}/ca.pem\n  certfile: {certs}/client.pem\n  keyfile: {certs}/server.key\n"
    assert config_error(tmp_path, mqtt) == (
        f"mqtt.keyfile: {certs}/server.key: not the key of mqtt.certfile {certs}/client.pem "
        "(KEY_VALUES_MISMATCH): give the key the certificate was made for")


@pytest.mark.parametrize(("certfile", "keyfile", "line"), [
    ("client.key", "client.key", "mqtt.certfile: {certs}/client.key: no certificate in it (it holds PRIVATE KEY): "
                                 "give the client certificate, PEM (-----BEGIN CERTIFICATE-----)"),
    ("client.pem", "client.pem", "mqtt.keyfile: {certs}/client.pem: no private key in it (it holds CERTIFICATE): "
                                 "give the client's key, PEM (-----BEGIN PRIVATE KEY-----)"),
    ("client.pem", "locked.key", "mqtt.keyfile: {certs}/locked.key: the key is encrypted (it asks for a "
                                 "passphrase): give it unencrypted (openssl pkey -in KEY -out PLAIN), readable "
                                 "by cmsensord only"),
])
def test_a_client_certificate_or_key_file_holding_the_wrong_thing_is_named(tmp_path, certs, certfile, keyfile,
                                                                           line):
    mqtt = f"  ca_file: {certs}/ca.pem\n  certfile: {certs}/{certfile}\n  keyfile: {certs}/{keyfile}\n"
    assert config_error(tmp_path, mqtt) == line.format(certs=certs)
