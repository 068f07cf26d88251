"""Import messages that name what is wrong: a time column whose clock steps back (left out of
the channels, the step named), a channel given twice, a text file that is not UTF-8 (read as
Latin-1, said), snapshots too short for a block (``--snapshot-len`` named)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

X = np.random.default_rng(0).normal(size=2000)


def _import(tmp_path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cmsensord", "import", *args, "--out", "o.bin"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60)


STEPS_BACK = ("column 'Time (s)' (0) is named as time but steps back 1 time(s), the first after row 1000 "
              "(0.999 -> 0.5): not a time base that gives the rate; it is not imported as a channel")


def _set_back(tmp_path):
    t = np.arange(X.size) / 1000
    t[1000:] -= 0.5
    (tmp_path / "x.csv").write_text("Time (s),acc\n" + "\n".join(f"{a:.4f},{b:.5f}" for a, b in zip(t, X)) + "\n")


def test_a_time_column_that_steps_back_is_no_channel_and_is_named(tmp_path):
    _set_back(tmp_path)
    r = _import(tmp_path, "x.csv", "--fs", "1000")
    assert r.returncode == 0, r.stderr
    assert "RAW, 1 channel(s), fs 1000 Hz" in r.stderr and "Time_s" not in r.stderr, r.stderr
    assert f"  note: {STEPS_BACK}\n" in r.stderr, r.stderr


def test_without_fs_the_error_names_the_time_column(tmp_path):
    _set_back(tmp_path)
    r = _import(tmp_path, "x.csv")
    assert (r.returncode, r.stdout, r.stderr) == (
        2, "", f"cmsensord import: x.csv: the file does not say its sampling rate: {STEPS_BACK}; give --fs HZ\n")


def test_a_channel_given_twice_is_refused(tmp_path):
    (tmp_path / "x.csv").write_text("a\n" + "\n".join(f"{v:.5f}" for v in X) + "\n")
    r = _import(tmp_path, "x.csv", "--fs", "1000", "--channels", "0,0")
    assert (r.returncode, r.stdout, r.stderr) == (
        2, "", "cmsensord import: --columns 0,0: column 'a' (0) given twice; give each once\n")
    assert not list(tmp_path.glob("o.bin*"))


def test_a_latin_1_file_is_read_as_latin_1_and_said(tmp_path):
    text = "t,Beschl\xe4u\n" + "\n".join(f"{i / 1000:.3f},{v:.5f}" for i, v in enumerate(X)) + "\n"
    (tmp_path / "x.csv").write_bytes(text.encode("latin-1"))
    r = _import(tmp_path, "x.csv")
    assert r.returncode == 0, r.stderr
    assert "  note: x.csv: not UTF-8 text: read as Latin-1 (ISO 8859-1)\n" in r.stderr, r.stderr
    assert "  note: channel 'Beschl\xe4u' is named Beschl_u" in r.stderr, r.stderr


def test_snapshots_shorter_than_a_block_name_snapshot_len(tmp_path):
    (tmp_path / "x.csv").write_text("a\n" + "\n".join(f"{v:.5f}" for v in X) + "\n")
    r = _import(tmp_path, "x.csv", "--fs", "1000", "--snapshot-len", "7")
    assert (r.returncode, r.stdout, r.stderr) == (
        2, "", "cmsensord import: --snapshot-len 7: snapshots of 7 sample(s) fill no 10-sample block; give a "
               "--snapshot-len of 10 or more, or a smaller --block-len\n")


def test_a_constant_column_in_g_is_said_constant_not_quantised(tmp_path):
    """A temperature column of 25.0 imported in g: removing its mean (245.2 m/s2) left ~1e-13 of
    rounding, read as a peak: full scale +-1.2e-13 m/s2 and no word that it never moves."""
    (tmp_path / "log.csv").write_text("acc,temp\n" + "\n".join(f"{a:.5f},25.0" for a in X) + "\n")
    p = _import(tmp_path, "log.csv", "--fs", "1000", "--unit", "g")
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if "temp" in ln]
    assert lines[0] == "  temp: full scale +-1 m/s2 (0.0004883 m/s2 a count), peak 0 m/s2, no clipping", lines
    assert ("  WARNING temp: every value is the same, a constant offset (no sensor on it?): calibrate cannot learn "
            "it; leave it out with --channels") in lines, lines
    assert not [ln for ln in lines if "counts RMS" in ln], lines
