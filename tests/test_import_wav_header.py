"""A WAV file whose header does not add up is one line and exit 2, nothing written: no
channels, no bytes a sample frame, a chunk running past the end of the file. A data chunk
that declares more bytes than the file holds is imported as far as it goes, with the note;
a float WAV with an inf in every block is refused as an empty channel is."""

from __future__ import annotations

import struct
import subprocess
import sys

import numpy as np
import pytest

PCM = (np.random.default_rng(1).normal(size=(800, 2)) * 3000).astype("<i2").tobytes()


def _wav(channels=2, align=4, fmt_size=16, before=b"", data=PCM, declared=None, kind=1, bits=16, rate=8000):
    fmt = struct.pack("<HHIIHH", kind, channels, rate, rate * align, align, bits)
    body = (b"WAVE" + b"fmt " + struct.pack("<I", fmt_size) + fmt + before + b"data"
            + struct.pack("<I", len(data) if declared is None else declared) + data)
    return b"RIFF" + struct.pack("<I", len(body)) + body


def _import(tmp_path, content: bytes) -> subprocess.CompletedProcess:
    (tmp_path / "x.wav").write_bytes(content)
    return subprocess.run([sys.executable, "-m", "cmsensord", "import", "x.wav", "--unit", "g", "--out", "o.bin"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("content, why", [
    (_wav(channels=0), "its fmt chunk gives 0 channels"),
    (_wav(align=0), "its fmt chunk gives a block align of 0 bytes"),
    (_wav(fmt_size=1_000_000), "its fmt chunk declares 1,000,000 bytes, past the end of the file"),
    (_wav(before=b"LIST" + struct.pack("<I", 0xFFFFFF00) + b"INFO"),
     "its LIST chunk declares 4,294,967,040 bytes, past the end of the file"),
], ids=["no-channels", "block-align-0", "fmt-too-long", "list-too-long"])
def test_a_header_that_does_not_add_up_is_one_line(tmp_path, content, why):
    r = _import(tmp_path, content)
    assert (r.returncode, r.stdout, r.stderr) == (
        2, "", f"cmsensord import: x.wav: not a readable WAV file ({why}); export it as PCM or float WAV\n")
    assert not list(tmp_path.glob("o.bin*"))


def test_a_data_chunk_longer_than_the_file_is_said(tmp_path):
    r = _import(tmp_path, _wav(declared=10 * len(PCM)))
    assert r.returncode == 0, r.stderr
    assert ("  note: x.wav: the file ends before the data its header declares (its data chunk declares 32,000 "
            "bytes, 3,200 are there); the 800 sample(s) there are imported\n") in r.stderr, r.stderr


def test_an_inf_in_every_block_is_refused(tmp_path):
    x = np.where(np.arange(800) % 5 == 0, np.inf, np.random.default_rng(2).normal(size=800)).astype("<f8")
    r = _import(tmp_path, _wav(channels=1, align=8, kind=3, bits=64, data=x.tobytes()))
    assert (r.returncode, r.stdout, r.stderr) == (
        2, "", "cmsensord import: ch0: a missing value (NaN, inf or empty) in every one of the 10 block(s): no "
               "block of it could be written; clean the file\n")
    assert not list(tmp_path.glob("o.bin*"))
