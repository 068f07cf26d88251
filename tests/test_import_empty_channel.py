"""`cmsensord import` with a channel that holds no value, or whose gaps take out many blocks:
each frame of the board carries every channel, so one channel's missing samples leave out
every channel's block.  A channel with no value at all is refused with a one-line message that
names the channels to keep (it wrote a capture of nothing but lost frames, and said "every value
is 0"); one whose gaps take out a tenth of the blocks or more is warned about."""

from __future__ import annotations

import numpy as np

from processes import run_module

FS = 2560


def _npz(path, b: np.ndarray) -> None:
    t = np.arange(b.size) / FS
    np.savez(path, a=2 * np.sin(2 * np.pi * 30 * t), b=b, fs=FS)


def test_a_channel_of_nothing_but_missing_values_is_refused(tmp_path):
    _npz(tmp_path / "r.npz", np.full(4 * FS, np.nan))
    out = tmp_path / "r.bin"
    p = run_module("cmsensord", "import", str(tmp_path / "r.npz"), "--array", "a,b", "--out", str(out))
    assert p.returncode == 2, p.stderr
    assert p.stderr == ("cmsensord import: b: no value in the recording (every one NaN, inf or empty): each frame "
                        "holds every channel, so no block could be written; import only a (--channels, or "
                        "--array / --variable for .npz / .mat)\n")
    assert not list(tmp_path.glob("r.bin*"))


def test_a_channel_whose_gaps_take_out_half_the_blocks_is_warned_about(tmp_path):
    b = np.sin(np.arange(4 * FS))
    b[:2 * FS] = np.nan
    _npz(tmp_path / "r.npz", b)
    p = run_module("cmsensord", "import", str(tmp_path / "r.npz"), "--array", "a,b", "--out", str(tmp_path / "r.bin"))
    assert p.returncode == 0, p.stderr
    assert ("  WARNING b: its missing samples leave out 50 % of the blocks, every channel's (a frame holds them "
            "all); leave it out (--channels, or --array / --variable for .npz / .mat) to keep them\n") in p.stderr
    assert "WARNING a:" not in p.stderr


def test_a_few_missing_samples_are_only_noted(tmp_path):
    b = np.sin(np.arange(4 * FS))
    b[100:110] = np.nan
    _npz(tmp_path / "r.npz", b)
    p = run_module("cmsensord", "import", str(tmp_path / "r.npz"), "--array", "a,b", "--out", str(tmp_path / "r.bin"))
    assert p.returncode == 0, p.stderr
    assert "WARNING" not in p.stderr
    assert "10 missing value(s) (NaN, inf or empty cells) in b (10), the first at sample 100" in p.stderr
