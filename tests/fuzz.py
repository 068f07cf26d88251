"""How many inputs the fuzz tests try: a short run in CI, a long one on demand.

    CMSENSORD_FUZZ_EXAMPLES=100000 python -m pytest -k fuzz     # the long (non-CI) mode

The decoder and config-loader fuzz tests take their ``max_examples`` from here.
"""

from __future__ import annotations

import os


def examples(ci: int) -> int:
    """``ci`` examples, or CMSENSORD_FUZZ_EXAMPLES when it is set (the long mode)."""
    value = os.environ.get("CMSENSORD_FUZZ_EXAMPLES")
    return int(value) if value else ci
