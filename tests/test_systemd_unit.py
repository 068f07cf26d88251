"""systemd/: the unit passes ``systemd-analyze verify`` silently and ``security`` at exposure <= 2.0,
keeps the hardening the serial link needs, and agrees with the example config, the udev rule and
the README's MQTT set-up (its root-only files reach the transient user as credentials)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from cmsensord.config import load_config
from cmsensord.config.mqtt import CREDENTIALS

ROOT = Path(__file__).resolve().parents[1]
UNIT = ROOT / "systemd" / "cmsensord.service"
EXAMPLE_CONFIG = ROOT / "systemd" / "cmsensord.yaml"
UDEV_RULE = ROOT / "systemd" / "99-cmsensord.rules"
EXEC_START = "/opt/cmsensord/bin/cmsensord --config /etc/cmsensord/cmsensord.yaml"
MAX_EXPOSURE = 2.0

ANALYZE = shutil.which("systemd-analyze")
needs_analyze = pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze is not installed "
                                   "(.ci/run installs Debian's systemd package when it is missing)")


def settings(text: str) -> dict[str, list[str]]:
    """KEY -> values, in order, of a unit file (comments and section headers left out)."""
    out: dict[str, list[str]] = {}
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith(("#", ";", "[")):
            key, _, value = line.partition("=")
            out.setdefault(key.strip(), []).append(value.strip())
    return out


def cmsensord_program(tmp_path: Path) -> str:
    """The cmsensord command of this environment: the console script `pip install` made, or
    (running from a source tree) a two-line launcher of ``python -m cmsensord``."""
    found = shutil.which("cmsensord", path=str(Path(sys.executable).parent)) or shutil.which("cmsensord")
    if found:
        return found
    launcher = tmp_path / "bin" / "cmsensord"
    launcher.parent.mkdir()
    launcher.write_text(f"#!/bin/sh\nPYTHONPATH={ROOT}${{PYTHONPATH:+:$PYTHONPATH}} "
                        f"exec {sys.executable} -m cmsensord \"$@\"\n")
    launcher.chmod(0o755)
    return str(launcher)


def installed_unit(tmp_path: Path, text: str | None = None) -> Path:
    """The unit as installed on this machine: only ExecStart's program path differs.

    verify checks that ExecStart's program exists and is executable, and /opt/cmsensord is
    where the README installs it, not where this test runs; the arguments stay as shipped.
    """
    text = UNIT.read_text() if text is None else text
    program = cmsensord_program(tmp_path)
    ran = subprocess.run([program, "--version"], capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0 and ran.stdout.startswith("cmsensord "), ran.stderr
    installed, n = re.subn(r"^ExecStart=/opt/cmsensord/bin/cmsensord ",
                           lambda _: f"ExecStart={program} ", text, flags=re.M)
    assert n == 1
    path = tmp_path / "cmsensord.service"
    path.write_text(installed)
    return path


def analyze(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([ANALYZE, *args], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, SYSTEMD_PAGER="", SYSTEMD_COLORS="0"))


def test_the_unit_is_a_watched_notify_service_that_keeps_restarting():
    s = settings(UNIT.read_text())
    assert s["ExecStart"] == [EXEC_START]
    assert s["Type"] == ["notify"] and s["NotifyAccess"] == ["main"]
    assert s["Restart"] == ["on-failure"]
    assert s["StartLimitIntervalSec"] == ["0"]            # restarts are never rate-limited away
    assert s["WatchdogSec"] and s["RestartSec"]


def test_the_unit_keeps_the_hardening_and_the_serial_port():
    s = settings(UNIT.read_text())
    expected = {
        "DynamicUser": "yes", "SupplementaryGroups": "dialout", "DevicePolicy": "closed",
        "ProtectSystem": "strict", "PrivateNetwork": "yes", "RestrictAddressFamilies": "AF_UNIX",
        "ProtectKernelTunables": "yes", "ProtectKernelModules": "yes", "ProtectKernelLogs": "yes",
        "ProtectControlGroups": "yes", "NoNewPrivileges": "yes", "StateDirectory": "cmsensord",
    }
    for key, value in expected.items():
        assert s.get(key) == [value], key
    assert "char-ttyACM rw" in s["DeviceAllow"]
    assert s["SystemCallFilter"][0] == "@system-service"
    assert s["MemoryMax"]
    # these would lower the exposure score and break the daemon: PrivateUsers= maps the dialout
    # group away, PrivateDevices= hides the tty
    assert s.get("PrivateUsers", ["no"]) == ["no"] and s.get("PrivateDevices", ["no"]) == ["no"]


def test_the_example_config_writes_to_the_state_directory_and_reads_the_udev_name():
    cfg = load_config(str(EXAMPLE_CONFIG))
    s = settings(UNIT.read_text())
    assert cfg.output.dir == f"/var/lib/{s['StateDirectory'][0]}"
    assert not cfg.output.status_line                      # STATUS= carries it, not the journal
    symlink = re.search(r'SYMLINK\+="([^"]+)"', UDEV_RULE.read_text()).group(1)
    assert cfg.link.port == f"/dev/{symlink}"


@needs_analyze
def test_systemd_analyze_verify_prints_nothing(tmp_path):
    unit = installed_unit(tmp_path)
    r = analyze("verify", "--man=no", str(unit))
    assert (r.returncode, r.stdout + r.stderr) == (0, "")


@needs_analyze
def test_systemd_analyze_verify_does_complain_here(tmp_path):
    """Control: on this machine verify does report a broken unit (so silence above means something)."""
    unit = installed_unit(tmp_path, UNIT.read_text().replace("ProtectSystem=strict", "ProtectSytem=strict"))
    r = analyze("verify", "--man=no", str(unit))
    assert "ProtectSytem" in r.stdout + r.stderr


@needs_analyze
def test_systemd_analyze_security_exposure_is_at_most_2(tmp_path):
    unit = installed_unit(tmp_path)
    r = analyze("security", "--offline=true", "--no-pager", str(unit))
    m = re.search(r"Overall exposure level for cmsensord\.service: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    assert float(m.group(1)) <= MAX_EXPOSURE, r.stdout


DROP_IN = ROOT / "systemd" / "cmsensord-mqtt.conf"


def with_drop_in(text: str) -> str:
    """The unit as systemd reads it with the MQTT drop-in: its [Service] lines after the unit's."""
    service = DROP_IN.read_text().split("[Service]", 1)[1]
    return text.replace("\n[Install]", f"\n{service}\n[Install]")


def test_the_mqtt_drop_in_opens_only_internet_sockets_to_the_listed_ranges():
    s = settings(with_drop_in(UNIT.read_text()))
    assert s["PrivateNetwork"][-1] == "no"
    assert s["RestrictAddressFamilies"][-1].split() == ["AF_UNIX", "AF_INET", "AF_INET6"]
    assert s["IPAddressDeny"] == ["any"] and "localhost" in s["IPAddressAllow"]


@needs_analyze
def test_systemd_analyze_with_the_mqtt_drop_in_verifies_and_stays_at_most_2(tmp_path):
    unit = installed_unit(tmp_path, with_drop_in(UNIT.read_text()))
    r = analyze("verify", "--man=no", str(unit))
    assert (r.returncode, r.stdout + r.stderr) == (0, "")
    r = analyze("security", "--offline=true", "--no-pager", str(unit))
    m = re.search(r"Overall exposure level for cmsensord\.service: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    assert float(m.group(1)) <= MAX_EXPOSURE, r.stdout


def credentials(text: str) -> dict[str, str]:
    """Credential id -> source file of each ``LoadCredential=`` line, commented out or not."""
    return dict(m.groups() for m in re.finditer(r"^#?LoadCredential=([^:\s]+):(\S+)$", text, re.M))


def test_the_readme_mqtt_setup_passes_the_root_only_files_as_credentials():
    """The service's transient user (DynamicUser=) cannot read the 0600 password file the README
    installs: the drop-in loads it as a credential and the README's config names the credential's
    path; a client key likewise (the drop-in's commented line, the README's keyfile)."""
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("## A fleet on one broker", 1)[1]
    installed = re.search(r"sudo install -m 0600 /dev/stdin (\S+)", section).group(1)
    mqtt = yaml.safe_load(section.split("```yaml\n", 1)[1].split("```", 1)[0])["mqtt"]
    assert settings(UNIT.read_text())["DynamicUser"] == ["yes"]
    loaded = settings(with_drop_in(UNIT.read_text()))["LoadCredential"]
    assert loaded == [f"mqtt.password:{installed}"]
    run_dir = f"/run/credentials/{UNIT.name}"
    assert CREDENTIALS == run_dir                        # the path the daemon's hint names
    assert mqtt["password_file"] == f"{run_dir}/mqtt.password"
    key = credentials(DROP_IN.read_text())["mqtt.key"]
    assert f"sudo install -m 0600 client.key {key}" in section
    assert f"keyfile: {run_dir}/mqtt.key" in " ".join(section.split())
