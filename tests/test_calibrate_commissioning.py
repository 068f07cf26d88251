"""`cmsensord calibrate` as a commissioning engineer uses it on an imported recording: what it
says of the healthy period is what the replay with its site file then does, the channels and
speed of the base configuration are the ones it learns with, and the site file is one for the
live board."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord


def _import(src: Path, *args: str) -> Path:
    cap = src.with_suffix(".bin")
    p = cmsensord("import", str(src), *args, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _severity(out_dir: Path, channel: str) -> list[tuple[float, dict]]:
    """(board second at the decision's end, its severity message) of a replay's log."""
    msgs = read_messages(next(out_dir.glob("*.mcap")))
    sev = [(t, m) for topic, t, m in msgs if topic == f"/cm/{channel}/severity"]
    t0 = sev[0][0] - 1_000_000_000          # the first decision ends 1 s after the first block
    return [(round((t - t0) / 1e9, 3), m) for t, m in sev]


@pytest.fixture(scope="module")
def run_in(tmp_path_factory) -> Path:
    """60 s of a bearing (80 blocks/s) whose first 15 s fluctuate more (a run-in), with one
    rough second (6-7 s) in them."""
    d = tmp_path_factory.mktemp("runin")
    rng = np.random.default_rng(4)
    x = rng.standard_normal(60 * 5120).reshape(-1, 64)
    amp = np.ones(x.shape[0])
    amp[:80 * 15] *= 1 + 0.2 * rng.standard_normal(80 * 15).clip(-3, 3)
    amp[80 * 6:80 * 7] *= 1 + 0.5 * rng.standard_normal(80).clip(-1.5, 1.5)
    np.save(d / "runin.npy", (0.5 * x * amp[:, None]).reshape(-1).astype(np.float32))
    return _import(d / "runin.npy", "--fs", "5120", "--block-len", "64", "--unit", "g", "--names", "de")


def test_the_run_in_decisions_are_checked_as_the_replay_grades_them(run_in, tmp_path):
    """The run-in is left out of the learning, but the monitor grades it: calibrate's margin and
    its count of flagged healthy decisions take it in (guards against 8 outliers at most and 0
    flagged while the replay flags 6-15 s), and say where they are, with the margin after the run-in;
    the replay flags exactly those."""
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(run_in), "--rpm", "1500", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert ("de: highest outlier count per decision on the healthy period at R_1: 37 against f_r 25 (margin "
            "0.68x, in the run-in (graded, not learned from); after it 8, margin 3.12x); 9 healthy decision(s) "
            "would be flagged (9 by R_1, 0 by their level >= 2 x baseline)\n"
            "de: R_1 flags 9 decision(s) of the healthy period, in 6.0-15.0 board s; 9 of them in its run-in "
            "(1.0-15.0 board s), which is not learned from but is graded all the same\n") in p.stdout
    p = cmsensord("replay", str(run_in), "--config", str(site), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    flagged = [t for t, m in _severity(tmp_path / "logs", "de") if m["severity_index"] > 0]
    assert flagged == [float(t) for t in range(7, 16)]


def test_a_configured_indicators_rpm_is_the_shaft_speed_and_the_line_says_so(run_in, tmp_path):
    """No tacho, no --rpm, no speed in the capture: indicators.rpm of --config is f_r (not the
    default monitor.f_r 28.66 Hz, "nothing gave this machine's shaft speed"), so the site file
    grades at the speed its bearing lines are computed at; --rpm still comes first."""
    base = tmp_path / "base.yaml"
    base.write_text("indicators:\n  rpm: 2000\n")
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(run_in), "--config", str(base), "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "\nde            33.333 indicators     4.904 " in p.stdout
    assert ("de: f_r 33.33 Hz from the configuration's indicators.rpm 2000 (no tacho, no --rpm): the decisions "
            "at the speed of the indicators' bearing lines and bands\n") in p.stdout
    assert "monitor.f_r" not in p.stdout
    cfg = yaml.safe_load(site.read_text())
    assert (cfg["indicators"]["rpm"], cfg["channels"][0]["f_r"]) == (2000, 33.33)
    assert "    f_r: 33.33                  # indicators.rpm 2000\n" in site.read_text()
    p = cmsensord("calibrate", str(run_in), "--config", str(base), "--rpm", "1500", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "\nde            25.000 --rpm          4.904 " in p.stdout and "indicators.rpm" not in p.stdout


def _records(out_dir: Path, channel: str) -> list[dict]:
    return [m for topic, _, m in read_messages(next(out_dir.glob("*.mcap"))) if topic == f"/cm/{channel}/indicators"]


def test_the_site_file_of_snapshots_leaves_their_record_length_to_the_capture(tmp_path):
    """FEMTO-like 0.1-s snapshots: calibrate learns with one record a snapshot, but the site file
    does not carry indicators.interval_s 0.1 (with it the live daemon on the port would write
    10 records a second, its velocity read high); a replay of the capture takes 0.1 s from
    its sidecar again, a continuous stream gets the configured 1-s records."""
    x = np.random.default_rng(6).standard_normal((100, 2560, 1)).astype(np.float32)
    np.savez(tmp_path / "snaps.npz", acc=x, fs=25600.0, t_s=np.arange(100) * 10.0)
    snaps = _import(tmp_path / "snaps.npz", "--unit", "g", "--names", "de")
    np.save(tmp_path / "stream.npy", x.reshape(-1))
    stream = _import(tmp_path / "stream.npy", "--fs", "25600", "--unit", "g", "--names", "de")
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(snaps), "--rpm", "1800", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert ("note: site.yaml does not carry indicators.interval_s 0.1 (the capture's snapshots'): the live board's "
            "continuous stream keeps records of 1 s; a replay of this capture takes 0.1 s from its sidecar again\n"
            ) in p.stdout
    text = site.read_text()
    assert "interval_s" not in (yaml.safe_load(text).get("indicators") or {})
    assert ("# indicators.interval_s is not set: the 0.1-s records of the capture's snapshots are its own (a replay\n"
            "# of it takes them from its sidecar); the live board's continuous stream keeps the configured length.\n"
            ) in text
    for cap, every in ((snaps, 0.1), (stream, 1.0)):
        out = tmp_path / f"logs_{cap.stem}"
        p = cmsensord("replay", str(cap), "--config", str(site), "--out", str(out))
        assert p.returncode == 0, p.stderr
        assert {m["interval_s"] for m in _records(out, "de")} == {every}


@pytest.fixture(scope="module")
def two_channels(tmp_path_factory) -> Path:
    """20 s of two bearings (80 blocks/s), imported."""
    d = tmp_path_factory.mktemp("two")
    np.save(d / "two.npy", np.random.default_rng(7).standard_normal((20 * 5120, 2)).astype(np.float32))
    return _import(d / "two.npy", "--fs", "5120", "--block-len", "64", "--unit", "g")


def test_a_configured_channel_the_capture_does_not_hold_is_said(two_channels, tmp_path):
    """BASE lists de, nde and fan; the capture holds two channels: calibrate says fan is not
    learned and not in the site file (not silently), and the replay warns that it is not
    monitored (a WARNING, not an INFO event); a rule naming fan is an error naming BASE (not
    calibrate's own temporary file, nor saying the channel was not defined)."""
    base = tmp_path / "base.yaml"
    base.write_text("channels:\n  - name: de\n  - name: nde\n  - name: fan\n")
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(two_channels), "--rpm", "1500", "--config", str(base), "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert (f"\nwarning: {base} lists channel(s) fan (index 2) that two.bin does not have (its 2 channel(s): de, "
            "nde): not learned, and left out of site.yaml: a daemon with it does not monitor them\n") in p.stdout
    assert [ch["name"] for ch in yaml.safe_load(site.read_text())["channels"]] == ["de", "nde"]
    p = cmsensord("replay", str(two_channels), "--config", str(base), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    assert ("WARNING config: board sends 2 channel(s); configured channel(s) fan (index 2) not in the stream: not "
            "monitored, their alarm rules and bearings see no value\n") in p.stderr

    base.write_text("channels:\n  - name: de\n  - name: nde\n  - name: fan\nalarms:\n  rules:\n"
                    "    - {name: fanv, indicator: velocity_rms_mm_s, channels: [fan], alert_zone: C}\n")
    site.unlink()
    p = cmsensord("calibrate", str(two_channels), "--rpm", "1500", "--config", str(base), "--out", str(site))
    assert (p.returncode, p.stderr) == (78, (
        f"cmsensord: configuration error: {base}: alarms.rules[0].channels: names fan, a channel two.bin does not "
        "have (its 2 channel(s): de, nde); the site file holds the channels calibrate learns from the capture: "
        "calibrate a capture that holds fan, or leave fan out of this file\n"))
    assert not site.exists() and not (tmp_path / "site.yaml.part").exists()


def test_a_faulty_capture_that_does_not_fit_or_does_not_change_r_max_is_said(two_channels, tmp_path):
    """--faulty of another set-up (another fs and block rate) is not used, one that lacks the
    channels leaves them R_n = 4 x R_1, and one that flags nothing above R_1 changes nothing:
    each said in one line (none accepted without a word); the site file's R_max is then
    the one learned without it."""
    rng = np.random.default_rng(8)
    np.save(tmp_path / "other.npy", rng.standard_normal((10 * 25600, 2)).astype(np.float32))
    np.save(tmp_path / "calm.npy", rng.standard_normal((10 * 5120, 2)).astype(np.float32))
    other = _import(tmp_path / "other.npy", "--fs", "25600", "--unit", "g")
    calm = _import(tmp_path / "calm.npy", "--fs", "5120", "--block-len", "64", "--unit", "g")
    named = tmp_path / "named.bin"
    p = cmsensord("import", str(tmp_path / "calm.npy"), "--fs", "5120", "--block-len", "64", "--unit", "g",
                  "--names", "de,nde", "--out", str(named))
    assert p.returncode == 0, p.stderr

    def calibrate(*faulty: str) -> tuple[list[str], list[float]]:
        site = tmp_path / "site.yaml"
        p = cmsensord("calibrate", str(two_channels), "--rpm", "1500", *faulty, "--out", str(site))
        assert p.returncode == 0, p.stderr
        said = [ln for ln in p.stdout.splitlines() if "faulty" in ln and not ln.startswith("R in units")]
        return said, [ch["r_max"] for ch in yaml.safe_load(site.read_text())["channels"]]

    plain = calibrate()
    assert plain[0] == []
    assert calibrate("--faulty", str(other)) == ([
        "warning: --faulty other.bin is not used: it is sampled at 25600 Hz, 100 blocks/s, the healthy capture at "
        "5120 Hz, 80 blocks/s (another machine or set-up?): R_max is R_n = 4 x R_1"], plain[1])
    assert calibrate("--faulty", str(named)) == ([
        "warning: --faulty named.bin has no channel ch_0, ch_1 (its channels: de, nde): their R_max is R_n = 4 x "
        "R_1"], plain[1])
    said, r_max = calibrate("--faulty", str(calm))
    assert r_max == plain[1]
    assert said == [f"{ch}: --faulty calm.bin did not change R_max: the largest R that flags half of its "
                    f"decisions, {r_f}, is not above R_1 {r_1}; R_n = 4 x R_1"
                    for ch, r_f, r_1 in (("ch_0", "0.0001995", "0.001265"), ("ch_1", "0.0001778", "0.001787"))]


@pytest.mark.parametrize("n, faulty", [(3, False), (1, True)])
def test_the_banks_r_1_is_the_one_calibrate_checked_and_reports(run_in, tmp_path, n, faulty):
    """Eq. (16) with few AKFs (n <= 4) or a --faulty R_max out of its reach: the site file's
    R_min, R_max give AKF_1 the R_1 the table reports and the healthy check ran at (guards against
    n 3 giving R_1 1.5 x the one reported, and n 1 with --faulty stopping on a ZeroDivisionError)."""
    from cmsensord.dsp.akf import bank_r

    base = tmp_path / "base.yaml"
    base.write_text(f"monitor:\n  n: {n}\n")           # no trace: its default AKF_10 not in the way
    more = []
    if faulty:
        y = np.random.default_rng(9).standard_normal(30 * 5120).reshape(-1, 64)
        amp = 1 + 0.6 * np.random.default_rng(10).standard_normal(y.shape[0]).clip(-1.5, 3)
        np.save(tmp_path / "bad.npy", (0.5 * y * amp[:, None]).reshape(-1).astype(np.float32))
        more = ["--faulty", str(_import(tmp_path / "bad.npy", "--fs", "5120", "--block-len", "64", "--unit", "g",
                                        "--names", "de"))]
    site = tmp_path / "site.yaml"
    p = cmsensord("calibrate", str(run_in), "--rpm", "1500", "--config", str(base), *more, "--out", str(site))
    assert p.returncode == 0, p.stderr
    row = next(ln for ln in p.stdout.splitlines() if ln.startswith("de "))
    r_1 = float(row.split()[8])
    ch = yaml.safe_load(site.read_text())["channels"][0]
    assert bank_r(ch["r_min"], ch["r_max"], n)[0] == pytest.approx(r_1, rel=1e-3), (row, ch)
    if faulty:
        assert f"de: R_1 = {r_1:.4g}: eq. 16 cannot reach R_max with R_1 = 4 x H = " in p.stdout, p.stdout
    else:
        assert ("de: R_n = 2.5 x R_1: with monitor.n <= 4 AKFs, eq. 16 cannot reach 4 x R_1 with R_min > 0 "
                "(R_min = R_1 / 4)\n") in p.stdout, p.stdout
        assert ch["r_max"] == pytest.approx(2.5 * r_1, rel=1e-3)
