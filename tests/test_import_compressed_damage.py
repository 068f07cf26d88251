"""`cmsensord import` of a compressed .npz or .mat with a damaged byte in its compressed data:
one line saying the file is corrupt, exit 2, no traceback (zlib.error came through as one)."""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.io

from processes import cmsensord

X = (np.sin(np.arange(20000) * 0.1) + 0.1 * np.random.default_rng(0).standard_normal(20000)).astype(np.float32)


def _damaged(tmp_path, kind: str):
    ok = tmp_path / f"ok.{kind}"
    if kind == "npz":
        np.savez_compressed(ok, acc=X)
    else:
        scipy.io.savemat(ok, {"acc": X[:, None].astype(np.float64)}, do_compression=True)
    data = bytearray(ok.read_bytes())
    data[58 if kind == "npz" else len(data) // 2] ^= 0xFF
    bad = tmp_path / f"bad.{kind}"
    bad.write_bytes(bytes(data))
    return bad


@pytest.mark.parametrize("kind, said", [
    ("npz", r"an array cannot be read \(Error -3 while decompressing data: [a-z ]+\): the archive is corrupt or cut "
            r"short; copy it again"),
    ("mat", r"a compressed variable is damaged \(Error -3 while decompressing data: [a-z ]+\): the file is corrupt "
            r"or cut short; copy it again"),
])
def test_a_damaged_compressed_file_is_one_line(tmp_path, kind, said):
    bad = _damaged(tmp_path, kind)
    p = cmsensord("import", str(bad), "--fs", "20000", "--out", str(tmp_path / "o.bin"))
    assert p.returncode == 2, p.stderr
    assert re.fullmatch(rf"cmsensord import: {re.escape(str(bad))}: {said}\n", p.stderr), p.stderr
    assert not (tmp_path / "o.bin").exists()
