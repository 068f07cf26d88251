"""A capture's sidecar made hostile (names by the thousand, more names than channels, JSON
nested past the parser's depth, whole numbers past a float's range or Python's 4,300 digits, a
file far larger than any import writes) costs a replay no more than a damaged one: one warning
line naming what is not used, the run goes on (exit 0), fast, never a traceback."""

from __future__ import annotations

import json
import shutil

import pytest

from processes import run_module

FS = 2000
SNAPSHOTS = "its snapshots (the records' length, the times in the recording) are not used"
UNREAD = "its channel names, units, speed and time line are not used"


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """A 1-channel capture of two 1-s snapshots at 2 kHz, imported at 1800 rpm."""
    d = tmp_path_factory.mktemp("rig")
    for k in range(2):
        (d / f"2004.02.12.10.{5 * k:02d}.39").write_text("\n".join(f"{(i * 7919 % 200) / 100 - 1:.2f}"
                                                                   for i in range(FS)) + "\n")
    p = run_module("cmsensord", "import", str(d), "--fs", str(FS), "--unit", "m/s2", "--rpm", "1800",
                   "--out", str(d / "r.bin"))
    assert p.returncode == 0, p.stderr
    return d


def _replayed(imported, tmp_path, text: str | None = None, edit=None, timeout=60):
    """``cmsensord replay`` of a copy of the capture whose sidecar is ``text``, or the import's
    changed by ``edit(meta)``: the capture's path and its stderr, once it exited 0."""
    cap = tmp_path / "r.bin"
    shutil.copy(imported / "r.bin", cap)
    if text is None:
        meta = json.loads((imported / "r.bin.json").read_text())
        edit(meta)
        text = json.dumps(meta)
    (tmp_path / "r.bin.json").write_text(text)
    p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"), timeout=timeout)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert "200 observations, 0 missing" in p.stderr, p.stderr
    return cap, p.stderr


def _warnings(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("warning: ")]


@pytest.mark.parametrize("names", [["x"] * 2000, list("abcdefghi"), ["a", "b"]], ids=["2000-alike", "nine", "two"])
def test_names_past_the_capture_s_channels_are_one_warning(imported, tmp_path, names):
    """Names past the channels the STATUS frames hold name none: the first is the channel's,
    the rest are said once and never made into names (2000 alike took 15 s, 100,000 forever)."""
    cap, err = _replayed(imported, tmp_path, edit=lambda m: m.__setitem__("channel_names", names), timeout=20)
    assert _warnings(err) == [f"warning: {cap}.json: the capture's sidecar's channel_names holds {len(names)} names, "
                              "its STATUS frames' 1 channel(s): the names past the first 1 are not used"], err
    assert f"\n  {names[0]}: final severity" in err and "not in the stream" not in err, err


def test_json_nested_past_the_parser_s_depth_is_not_read(imported, tmp_path):
    cap, err = _replayed(imported, tmp_path, "[" * 100_000 + "]" * 100_000)
    assert _warnings(err) == [f"warning: {cap}.json: the capture's sidecar cannot be read (nested too deeply): "
                              f"{UNREAD}"], err


@pytest.mark.parametrize("depth", [40, 985])
def test_a_field_nested_within_the_parser_s_depth_is_not_read(imported, tmp_path, depth):
    """A field nested deeper than any import writes is the same one line, whatever the depth:
    985 parsed within the parser's depth, and the warning quoting the field ran out of stack
    (a RecursionError traceback, exit 1); 40 was quoted as a field that is no number."""
    cap, err = _replayed(imported, tmp_path, '{"fs": ' + "[" * depth + "]" * depth + "}")
    assert _warnings(err) == [f"warning: {cap}.json: the capture's sidecar cannot be read (nested too deeply): "
                              f"{UNREAD}"], err


BIG = 10 ** 309     # past a float's range
SHOWN = "1" + "0" * 36 + "..."


def _snap(k, key, value):
    return lambda meta: meta["snapshots"][k].__setitem__(key, value)


@pytest.mark.parametrize("edit, said", [
    (lambda m: m.__setitem__("rpm", BIG), f"rpm is {SHOWN} (not a speed in rpm): its speed is not used"),
    (lambda m: m.__setitem__("fs", BIG), f"fs is {SHOWN} (not a positive number): the STATUS frames' 2000 Hz is used"),
    (_snap(1, "start_s", BIG), f"snapshots[1].start_s is {SHOWN} (not a board second): {SNAPSHOTS}"),
    (_snap(0, "length", BIG), f"snapshots[0].length is {SHOWN} (not a number of samples): {SNAPSHOTS}"),
    (_snap(1, "length", 2 ** 60), f"snapshots[1].length is {2 ** 60} (not a number of samples): {SNAPSHOTS}"),
], ids=["rpm", "fs", "start_s", "length", "length-past-2**53"])
def test_a_whole_number_past_a_float_is_one_warning(imported, tmp_path, edit, said):
    cap, err = _replayed(imported, tmp_path, edit=edit)
    assert _warnings(err) == [f"warning: {cap}.json: the capture's sidecar's {said}"], err


def test_a_whole_number_past_python_s_4300_digits_is_one_warning(imported, tmp_path):
    text = (imported / "r.bin.json").read_text()
    assert '"rpm": 1800.0' in text
    cap, err = _replayed(imported, tmp_path, text.replace('"rpm": 1800.0', '"rpm": -' + "9" * 5000))
    assert _warnings(err) == [f"warning: {cap}.json: the capture's sidecar's rpm is -Infinity (not a speed in rpm): "
                              "its speed is not used"], err


def test_a_sidecar_larger_than_any_import_s_is_refused_unread(imported, tmp_path):
    """64 MiB holds 200,000 snapshots (IMS's 6,324 take 2 MB); one byte more is said from its
    size, never read (a sparse file: nothing written)."""
    side = tmp_path / "r.bin.json"
    with open(side, "wb") as f:
        f.truncate((64 << 20) + 1)
    cap = tmp_path / "r.bin"
    shutil.copy(imported / "r.bin", cap)
    p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"))
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert _warnings(p.stderr) == [f"warning: {side}: the capture's sidecar cannot be read (67,108,865 bytes, over the "
                                   f"67,108,864 read of a sidecar: not an import's): {UNREAD}"], p.stderr
