"""A real recording through the user's path: import -> calibrate -> replay (IMS bearing rig).

Calibrated on the first half (3 s) of the healthy segment, the second half stays at 0
and the inner-race fault is flagged.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

DATA = Path(__file__).parent / "data" / "ims"


def cmsensord(*args):
    p = run_module("cmsensord", *args)
    assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    work = tmp_path_factory.mktemp("ims")
    for name in ("NA", "IF"):
        cmsensord("import", str(DATA / f"{name}.mat"), "--variable", "data", "--fs", "20480", "--unit", "g",
                  "--names", "bearing", "--out", str(work / f"{name}.bin"))
    p = cmsensord("calibrate", str(work / "NA.bin"), "--to", "3", "--rpm", "2000",
                  "--out", str(work / "site.yaml"))
    assert "bearing" in p.stdout and "0 healthy decision(s) would be flagged" in p.stdout
    return work


def severity(work: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    out = work / f"logs_{name}"
    cmsensord("replay", str(work / f"{name}.bin"), "--config", str(work / "site.yaml"), "--out", str(out))
    sev = [(t, m["severity_index"]) for topic, t, m in read_messages(next(out.glob("*.mcap")))
           if topic == "/cm/bearing/severity"]
    t = np.array([s[0] for s in sev]) - sev[0][0]
    return t / 1e9 + 1.0, np.array([s[1] for s in sev])     # board seconds at each decision's end


def test_the_healthy_second_half_stays_at_zero(site):
    t, sev = severity(site, "NA")
    assert t.size == 5 and np.all(sev[t > 3.01] == 0.0)


def test_the_inner_race_fault_is_flagged(site):
    _, healthy = severity(site, "NA")
    _, fault = severity(site, "IF")
    assert fault.mean() > healthy.mean() and fault.max() >= 0.5
