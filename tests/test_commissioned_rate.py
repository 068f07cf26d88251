"""calibrate writes what it learned the baselines from (``commissioned``: the capture's real path,
its board's fs and block length, the healthy period in its board seconds); a replay or a daemon
on a board at another rate (another machine's site file: a FEMTO recording at 25.6 kHz replayed
with the simulated motor's) says so once, at the STATUS, and a re-calibration on top writes its own."""

from __future__ import annotations

import hashlib
import os

import numpy as np
import pytest
import yaml

from processes import cmsensord, run_module


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("commissioned")
    sim = run_module("firmware_sim", "--scenario", "healthy", "--duration", "60", "--out", d / "motor.bin")
    assert sim.returncode == 0, sim.stderr
    p = cmsensord("calibrate", str(d / "motor.bin"), "--out", str(d / "site.yaml"))
    assert p.returncode == 0, p.stderr
    import scipy.io.wavfile
    t = np.arange(20480 * 20) / 20480
    x = 0.3 * np.sin(2 * np.pi * 30 * t) + 0.05 * np.random.default_rng(1).standard_normal(t.size)
    scipy.io.wavfile.write(d / "other.wav", 20480, x.astype(np.float32))
    p = cmsensord("import", str(d / "other.wav"), "--unit", "g", "--out", str(d / "other.bin"))
    assert p.returncode == 0, p.stderr
    return d


def _print(path) -> dict:
    """The size and the SHA-256 of the first and last 64 KiB calibrate writes of a capture."""
    data = path.read_bytes()
    ends = data[:1 << 16] + data[max(1 << 16, len(data) - (1 << 16)):]
    return {"capture_bytes": len(data), "capture_ends_sha256": hashlib.sha256(ends).hexdigest()}


def said(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "baselines were learned from" in ln]


def test_calibrate_writes_the_capture_and_its_rate(work):
    assert yaml.safe_load((work / "site.yaml").read_text())["commissioned"] == {
        "capture": os.path.realpath(work / "motor.bin"), **_print(work / "motor.bin"), "fs_hz": 25000,
        "block_len": 250, "from_s": 0.0,
        "to_s": 60.0}


def test_a_replay_of_the_same_board_says_nothing(work, tmp_path):
    p = cmsensord("replay", str(work / "motor.bin"), "--config", str(work / "site.yaml"), "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr
    assert said(p.stderr) == [], p.stderr


def test_a_replay_of_a_board_at_another_rate_is_warned_once(work, tmp_path):
    p = cmsensord("replay", str(work / "other.bin"), "--config", str(work / "site.yaml"), "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr
    assert said(p.stderr) == [
        "WARNING config: the baselines were learned from motor.bin at fs 25000 Hz, block 250; this board sends fs "
        "20480 Hz, block 205: they and the alarm levels on them may not fit it (cmsensord calibrate on this "
        "machine's healthy period)"], p.stderr


def test_a_calibration_on_top_of_a_site_file_writes_its_own(work, tmp_path):
    p = cmsensord("calibrate", str(work / "other.bin"), "--config", str(work / "site.yaml"),
                  "--out", str(tmp_path / "site2.yaml"))
    assert p.returncode == 0, p.stderr
    assert yaml.safe_load((tmp_path / "site2.yaml").read_text())["commissioned"] == {
        "capture": os.path.realpath(work / "other.bin"), **_print(work / "other.bin"), "fs_hz": 20480,
        "block_len": 205, "from_s": 0.0,
        "to_s": 19.999512}     # its 1998 whole blocks of 205 samples
    p = cmsensord("replay", str(work / "other.bin"), "--config", str(tmp_path / "site2.yaml"), "--out",
                  str(tmp_path / "logs"))
    assert said(p.stderr) == [], p.stderr
