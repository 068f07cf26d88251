"""The ``mqtt`` section's errors a user meets at start, through ``cmsensord --config FILE``: a
host written as a URL, TLS files that are not what their setting is for, and files it cannot
read (under systemd, with how to pass them as credentials). Each is one line naming the key and
the file, exit status 78, before any connection is tried."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from mosquitto import make_certificates
from processes import ENV, cmsensord

EXIT_CONFIG = 78


def config_error(tmp_path: Path, mqtt: str, host: str = "127.0.0.1", env: dict | None = None) -> str:
    """The one stderr line of ``cmsensord --config`` with this mqtt section (exit 78, ``env``: the
    environment, default ENV), less its ``cmsensord: configuration error: FILE: `` head."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"output:\n  dir: {tmp_path / 'logs'}\nmqtt:\n  host: {host}\n{mqtt}")
    p = cmsensord("--config", str(cfg), timeout=30, env=env)   # a config that passes starts the daemon
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


def without_root_override() -> list[str]:
    """The command prefix that runs a process unable to read a mode-0 file it owns, as the
    service's transient user cannot read root's 0600 file: as root, setpriv drops the two
    capabilities that override file permissions; else none is needed."""
    if os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("setpriv (util-linux) is not installed")
    return ["setpriv", "--bounding-set=-dac_override,-dac_read_search"]


@pytest.mark.parametrize("key", ["password_file", "keyfile"])
def test_a_file_the_service_user_cannot_read_says_under_systemd_how_to_pass_it(tmp_path, certs, key):
    """README "The password and a client key under systemd": exit 78, and under systemd
    (INVOCATION_ID) the line names the LoadCredential= line and the credential's path."""
    secret = tmp_path / ("mqtt.password" if key == "password_file" else "mqtt.key")
    secret.write_bytes(b"pw\n" if key == "password_file" else (certs / "client.key").read_bytes())
    secret.chmod(0)
    mqtt = (f"  username: rig\n  password_file: {secret}\n" if key == "password_file" else
            f"  ca_file: {certs}/ca.pem\n  certfile: {certs}/client.pem\n  keyfile: {secret}\n")
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"output:\n  dir: {tmp_path / 'logs'}\nmqtt:\n  host: 127.0.0.1\n{mqtt}")
    plain = f"mqtt.{key}: cannot read: Permission denied"
    for env, line in (
            ({}, plain),
            ({"INVOCATION_ID": "5f3c0e1a9b7d4c2e8a6f1b3d5c7e9a0b"},
             f"{plain}; the service's user cannot read it: give it to the service with LoadCredential="
             f"{secret.name}:{secret} (systemd/cmsensord-mqtt.conf) and set mqtt.{key}: "
             f"/run/credentials/cmsensord.service/{secret.name}")):
        run_env = {k: v for k, v in ENV.items() if k != "INVOCATION_ID"} | env
        p = subprocess.run([*without_root_override(), sys.executable, "-m", "cmsensord", "--config", str(cfg)],
                           capture_output=True, text=True, env=run_env, timeout=60)
        assert p.returncode == EXIT_CONFIG, p.stderr
        (got,) = p.stderr.strip().splitlines()              # " (got '<path>')" cut short when long
        assert got.rpartition(" (got ")[0] == f"cmsensord: configuration error: {cfg}: {line}", got


def test_a_credential_the_unit_does_not_load_is_named_under_systemd(tmp_path):
    missing = "/run/credentials/cmsensord-test-absent.service/mqtt.password"
    env = dict(ENV, INVOCATION_ID="5f3c0e1a9b7d4c2e8a6f1b3d5c7e9a0b")
    line = config_error(tmp_path, f"  username: rig\n  password_file: {missing}\n", env=env)
    assert line.rpartition(" (got ")[0] == (
        "mqtt.password_file: cannot read: No such file or directory; the unit loads no credential "
        "mqtt.password: add LoadCredential=mqtt.password:<the file> to its drop-in "
        "(systemd/cmsensord-mqtt.conf)")


def test_the_services_credential_path_does_not_stop_a_command_run_by_hand(tmp_path):
    """The README's MQTT setup names the password as the unit's credential (there only while
    the service runs): `cmsensord replay --config <the service's configuration>` run by hand
    replays, one line says the credential was not checked (it exited 78 on it)."""
    cap = tmp_path / "cap.bin"
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--duration", "3",
                        "--out", str(cap)], env=ENV, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    path = "/run/credentials/cmsensord.service/mqtt.password"
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"mqtt:\n  host: 127.0.0.1\n  username: rig\n  password_file: {path}\n")
    env = {k: v for k, v in ENV.items() if k != "INVOCATION_ID"}
    p = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "o"), env=env)
    assert p.returncode == 0, p.stderr
    assert (f"WARNING config: mqtt.password_file {path}: not checked: the service's credential(s), there only "
            "while the unit runs") in p.stderr.splitlines(), p.stderr
