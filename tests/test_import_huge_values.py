"""Values no capture can hold are one line and exit 2, nothing written: a rate past STATUS's
32-bit fs field, a full scale whose float32 scale would be infinite (a logger's 1.8e308
no-value mark, values of 1e300, ``--range 1e300``). A value that ``--scale-factor`` takes
past float64 is a missing value, as NaN is."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

X = np.random.default_rng(0).normal(size=2000)


def _import(tmp_path, column, *args) -> subprocess.CompletedProcess:
    (tmp_path / "x.csv").write_text("a\n" + "\n".join(column) + "\n")
    return subprocess.run([sys.executable, "-m", "cmsensord", "import", "x.csv", *args, "--out", "o.bin"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=60)


TOO_LARGE = ("past the largest full scale the board's STATUS carries (+-6.97e+41 m/s2: its scale is a float32); "
             "check --unit and --scale-factor, or a logger's no-value mark (1.8e308) in the file")


@pytest.mark.parametrize("column, args, message", [
    ([f"{v:.5f}" for v in X], ("--fs", "1e300", "--mode", "rms"),
     "--fs 1e+300: more than the board protocol carries (STATUS fs: at most 4,294,967,295 Hz); check --fs"),
    ([f"{v:.5f}" for v in X], ("--fs", "1e300"),
     "--fs 1e+300: more than the board protocol carries (STATUS fs: at most 4,294,967,295 Hz); check --fs"),
    ([f"{v:.5f}" for v in X], ("--fs", "1e7", "--mode", "rms"),
     "fs 10000000 Hz: blocks of fs/100 = 100,000 samples, more than STATUS carries (65535); give --block-len"),
    (["1.7976931348623157e+308"] + [f"{v:.5f}" for v in X[1:]], ("--fs", "1000"),
     f"a: peak 1.797e+308 m/s2, {TOO_LARGE}"),
    ([f"{v * 1e300:.5e}" for v in X], ("--fs", "1000"), f"a: peak 3.871e+300 m/s2, {TOO_LARGE}"),
    ([f"{v:.5f}" for v in X], ("--fs", "1000", "--scale-factor", "1e300"), f"a: peak 3.871e+300 m/s2, {TOO_LARGE}"),
    ([f"{v:.5f}" for v in X], ("--fs", "1000", "--range", "1e300"),
     "--range 1e+300: past the largest full scale the board's STATUS carries (+-6.97e+41: its scale, a count's "
     "value, is a float32)"),
], ids=["fs-rms", "fs-raw", "block-rms", "dbl-max-cell", "values-1e300", "scale-factor", "range"])
def test_what_no_capture_holds_is_one_line(tmp_path, column, args, message):
    r = _import(tmp_path, column, *args)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n")
    assert not list(tmp_path.glob("o.bin*"))


def test_a_value_scaled_past_float64_is_missing(tmp_path):
    column = [f"{v:.5f}" for v in X]
    column[500] = "1e300"
    r = _import(tmp_path, column, "--fs", "1000", "--scale-factor", "1e10")
    assert r.returncode == 0 and "Warning" not in r.stderr, r.stderr
    assert ("  note: x.csv: 1 missing value(s) (NaN, inf or empty cells) in a (1), the first at sample 500: the "
            "blocks that hold them are left out of the capture") in r.stderr, r.stderr
