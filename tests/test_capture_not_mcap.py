"""A file that is not a capture given where one goes (replay, calibrate, vkf): an MCAP log, a
file with no frame in it (a YAML file, a WAV), a capture whose every frame fails its CRC check:
one line naming it and what to do, exit 2, no output (a replay wrote an empty log and a
decode_error, exit 0; calibrate said "no observations (no RMS or RAW frames)")."""

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


@pytest.fixture(scope="module")
def crc_broken(tmp_path_factory):
    """A 3-s capture with the CRC of each of its frames flipped: frames, none of them good."""
    work = tmp_path_factory.mktemp("crc")
    sim = run_module("firmware_sim", "--scenario", "healthy", "--duration", "3", "--out", work / "cap.bin")
    assert sim.returncode == 0, sim.stderr
    data, at, n = bytearray((work / "cap.bin").read_bytes()), 0, 0
    while at < len(data):
        assert data[at:at + 2] == b"\xa5\x5a"
        length = int.from_bytes(data[at + 12:at + 14], "little")
        data[at + 14 + length] ^= 0xFF
        at, n = at + 18 + length, n + 1
    (work / "bad.bin").write_bytes(data)
    return work / "bad.bin", n


@pytest.mark.parametrize("command", ["replay", "calibrate", "vkf"])
def test_a_file_with_no_frame_is_named_as_not_a_capture(tmp_path, command):
    site = tmp_path / "site.yaml"
    site.write_text("channels:\n  - {name: motor, index: 0}\n" * 40)
    out = tmp_path / "out"
    p = cmsensord(command, str(site), "--out", str(out))
    assert p.returncode == 2, p.stderr
    assert p.stderr == (f"cmsensord: {command}: no frame in {site} ({site.stat().st_size} bytes): not a capture of "
                        "the board's serial stream? (`cmsensord import` makes one from other recordings)\n")
    assert not out.exists()


@pytest.mark.parametrize("command", ["replay", "calibrate", "vkf"])
def test_a_capture_of_frames_all_failing_their_crc_is_refused(crc_broken, tmp_path, command):
    bad, frames = crc_broken
    out = tmp_path / "out"
    out.mkdir()                         # an --out that is there stays as it was: empty
    p = cmsensord(command, str(bad), "--out", str(out / "site.yaml" if command == "calibrate" else out))
    assert p.returncode == 2, p.stderr
    assert p.stderr == (f"cmsensord: {command}: no frame in {bad} ({bad.stat().st_size} bytes): all {frames} "
                        "frame(s) in it failed their CRC check: a damaged capture (copied as text?): copy or "
                        "record it again\n")
    assert list(out.iterdir()) == []
