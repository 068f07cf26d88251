"""A command whose ``--out`` names one of its own inputs refuses, in one line, before it reads
anything, and the input is left as it was (import wrote its capture over the WAV it read,
report its HTML page over the log, calibrate its site file over the capture)."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from processes import run_module


def capture_file(tmp_path, scenario: str, seconds: int):
    """A capture of the simulated board (``python -m firmware_sim --out``)."""
    path = tmp_path / f"{scenario}.bin"
    p = run_module("firmware_sim", "--scenario", scenario, "--duration", str(seconds), "--out", str(path))
    assert p.returncode == 0, p.stderr
    return path


def _expect_refusal(p, prefix: str, out, src) -> None:
    assert p.returncode == 2, p.stderr
    assert p.stderr.splitlines()[-1] == (f"{prefix}{out}: is the input {src}: writing it would destroy it; give "
                                         "--out another file name"), p.stderr


def test_import_over_its_own_recording(tmp_path):
    src = tmp_path / "x.npy"
    np.save(src, np.sin(np.arange(20000) / 10.0))
    before = src.read_bytes()
    p = run_module("cmsensord", "import", str(src), "--fs", "2000", "--out", str(src))
    _expect_refusal(p, "cmsensord import: ", src, src)
    assert src.read_bytes() == before and not (tmp_path / "x.npy.json").exists()


def test_calibrate_over_its_capture_or_through_a_link(tmp_path):
    cap = capture_file(tmp_path, "healthy", 60)
    before = cap.read_bytes()
    p = run_module("cmsensord", "calibrate", str(cap), "--out", str(cap))
    _expect_refusal(p, "cmsensord: calibrate: ", cap, cap)
    link = tmp_path / "site.yaml"
    os.symlink(cap, link)
    p = run_module("cmsensord", "calibrate", str(cap), "--out", str(link))
    _expect_refusal(p, "cmsensord: calibrate: ", link, cap)
    assert cap.read_bytes() == before
    side = tmp_path / "healthy.bin.json"              # an import's sidecar: channel names, snapshots
    side.write_text("{}")
    p = run_module("cmsensord", "calibrate", str(cap), "--out", str(side))
    _expect_refusal(p, "cmsensord: calibrate: ", side, side)
    assert side.read_text() == "{}"


def test_report_over_its_log(tmp_path):
    pytest.importorskip("matplotlib")
    cap = capture_file(tmp_path, "healthy", 20)
    assert run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "logs")).returncode == 0
    log = next((tmp_path / "logs").glob("*.mcap"))
    before = log.read_bytes()
    p = run_module("cmsensord", "report", str(tmp_path / "logs"), "--out", str(log))
    _expect_refusal(p, "cmsensord: ", log, log)
    assert log.read_bytes() == before


def test_acoustic_calibration_over_a_capture(tmp_path):
    cap = capture_file(tmp_path, "healthy", 5)
    other = tmp_path / "bg.bin"
    shutil.copy(cap, other)
    p = run_module("cmsensord.acoustic_calib", "--paired", str(cap), "--background", str(other), "--out", str(other))
    _expect_refusal(p, "acoustic_calib: error: ", other, other)
    assert other.read_bytes() == cap.read_bytes()
