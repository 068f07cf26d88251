"""Without a C compiler (the kernels not built): the daemon runs its numpy fallbacks and
never imports scipy (~70 MB resident), through the command a user types."""

from __future__ import annotations

import json
import subprocess
import sys

from processes import ENV

#: the daemon as `cmsensord --simulate ...` runs it, with the compiled kernels unimportable
#: (as when `pip install` found no compiler); prints what it imported
CODE = """
import json, sys
for name in ("cmsensord.dsp._akfkernel", "cmsensord.dsp._trackerkernel", "cmsensord._wirekernel"):
    sys.modules[name] = None
from cmsensord.cli import main
rc = main(sys.argv[1:])
from cmsensord import wire_scan
from cmsensord.dsp import akf, order_tracker
print(json.dumps({"rc": rc, "akf_kernel": akf.have_kernel(), "tracker_kernel": order_tracker.have_kernel(),
                  "wire_kernel": wire_scan.have_kernel(),
                  "scipy": sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy."))}))
"""


def test_the_daemon_without_the_kernels_tracks_orders_and_imports_no_scipy(tmp_path):
    p = subprocess.run([sys.executable, "-c", CODE, "--simulate", "--scenario", "faulty", "--mode", "raw",
                        "--tacho", "--duration", "4", "--speed", "4", "--out", str(tmp_path)],
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got == {"rc": 0, "akf_kernel": False, "tracker_kernel": False, "wire_kernel": False, "scipy": []}
    from cmsensord.sinks.mcap_sink import read_messages

    orders = [m for t, _, m in read_messages(next(tmp_path.glob("*.mcap"))) if t == "/cm/ch0/orders"]
    assert len(orders) >= 25 and any(m["valid"] for m in orders)
