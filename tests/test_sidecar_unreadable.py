"""A capture's sidecar that cannot be read (truncated, not an object) is said on one line,
once, and the replay goes on with the capture alone (not silently on default names)."""

from __future__ import annotations

import numpy as np
import pytest

from test_import_records import _run


@pytest.mark.parametrize("text, why", [
    (None, "Unterminated string starting at: line "),
    ("[1, 2]\n", "not a JSON object"),
])
def test_an_unreadable_sidecar_is_said_once(tmp_path, text, why):
    np.savez(tmp_path / "r.npz", acc=np.random.default_rng(0).standard_normal(20000), fs=5000.0)
    cap = tmp_path / "r.bin"
    _run("import", tmp_path / "r.npz", "--unit", "m/s2", "--names", "spindle", "--out", cap)
    side = tmp_path / "r.bin.json"
    side.write_text(side.read_text()[:100] if text is None else text)
    err = _run("replay", cap, "--out", tmp_path / "out")
    said = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert len(said) == 1 and said[0].startswith(f"warning: {side}: the capture's sidecar cannot be read ({why}"), err
    assert said[0].endswith("): its channel names, units, speed and time line are not used"), said
    assert "  ch0: final severity" in err and "spindle" not in err
