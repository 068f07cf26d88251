"""`cmsensord calibrate CAPTURE --config OLD_SITE.yaml` (re-commissioning) says what it changes:
the capture's channels the old file does not list (not learned), the baselines it replaces, and
the alarm rules it could not judge because the capture's records do not carry their indicator."""

from __future__ import annotations

import subprocess
import sys

import pytest

from processes import ENV


def run(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, env=ENV, timeout=120)


@pytest.fixture(scope="module")
def caps(tmp_path_factory):
    d = tmp_path_factory.mktemp("recal")
    for name, scenario, channels in (("healthy", "healthy", "1"), ("healthy2", "healthy", "2"),
                                     ("faulty", "faulty", "1")):
        p = run("firmware_sim", "--scenario", scenario, "--duration", "40", "--channels", channels, "--seed", "5",
                "--out", str(d / f"{name}.bin"))
        assert p.returncode == 0, p.stderr
    p = run("cmsensord", "calibrate", str(d / "healthy.bin"), "--out", str(d / "site1.yaml"))
    assert p.returncode == 0, p.stderr
    return d


def test_a_capture_channel_the_old_site_file_does_not_list_is_warned_of(caps, tmp_path):
    p = run("cmsensord", "calibrate", str(caps / "healthy2.bin"), "--config", str(caps / "site1.yaml"),
            "--out", str(tmp_path / "site2.yaml"))
    assert p.returncode == 0, p.stderr
    assert (f"warning: healthy2.bin has 2 channel(s); {caps / 'site1.yaml'} lists 1 (ch0 (index 0)): channel "
            f"index(es) 1 not learned, and left out of site2.yaml: add them to {caps / 'site1.yaml'}'s channels "
            "(name, index) to monitor them") in p.stdout.splitlines(), p.stdout
    assert "replaces BASE's" not in p.stdout        # the same machine's healthy level: within 1 %


def test_the_baselines_replaced_are_said_old_to_new(caps, tmp_path):
    p = run("cmsensord", "calibrate", str(caps / "faulty.bin"), "--config", str(caps / "site1.yaml"),
            "--out", str(tmp_path / "site1b.yaml"))
    assert p.returncode == 0, p.stderr
    notes = [ln for ln in p.stdout.splitlines() if ln.startswith("note: site1b.yaml: ")]
    assert len(notes) == 2, p.stdout
    old, new, ratio = (float(x) for x in
                       notes[0].removeprefix("note: site1b.yaml: ch0 baseline ").removesuffix(") replaces BASE's")
                       .replace(" -> ", " ").replace(" (x", " ").split())
    assert new > 2 * old and ratio == pytest.approx(new / old, rel=2e-3), notes[0]
    assert notes[1].startswith("note: site1b.yaml: 1 of BASE's 1 alarms.baselines value(s) replaced; the largest "
                               "change accel_rms on ch0 "), notes[1]


def test_rules_on_indicators_an_rms_capture_does_not_carry_are_said_not_judged(caps, tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("alarms:\n  rules:\n    - {name: k, indicator: kurtosis, alert: 0.001}\n"
                    "    - {name: s, indicator: severity_index, alert: 0.5}\n")
    p = run("cmsensord", "calibrate", str(caps / "healthy.bin"), "--config", str(base),
            "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("alarm")]
    assert lines == ["alarms: none of the 1 judged rule(s) shown within the healthy period (replayed with the "
                     "site file)",
                     "alarms: rule(s) k not judged: the capture's indicator records carry no kurtosis (an RMS-mode "
                     "board's carry accel_rms alone)"], p.stdout
