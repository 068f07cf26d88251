"""An MCAP log given where a capture goes (replay, calibrate, vkf): one line naming it and what
reads it, exit 2, no output (a replay wrote an empty log and a decode_error; calibrate said
"no observations (no RMS or RAW frames)")."""

from __future__ import annotations

import pytest

from processes import cmsensord, run_module


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    work = tmp_path_factory.mktemp("mcap")
    sim = run_module("firmware_sim", "--scenario", "healthy", "--duration", "3", "--out", work / "cap.bin")
    assert sim.returncode == 0, sim.stderr
    p = cmsensord("replay", str(work / "cap.bin"), "--out", str(work / "logs"))
    assert p.returncode == 0, p.stderr
    (path,) = (work / "logs").glob("*.mcap")
    return path


@pytest.mark.parametrize("command", ["replay", "calibrate", "vkf"])
def test_an_mcap_log_is_named_as_not_a_capture(log, tmp_path, command):
    p = cmsensord(command, str(log), "--out", str(tmp_path / "out"))
    assert p.returncode == 2, p.stderr
    assert p.stderr == (f"cmsensord: {log}: an MCAP log (cmsensord's output), not a capture of the board's serial "
                        "stream: `cmsensord summary` and `cmsensord report` read it; replay, calibrate and vkf read "
                        "a capture (`--capture`, `cmsensord record`, `cmsensord import`)\n")
    assert not (tmp_path / "out").exists()
