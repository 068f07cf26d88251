"""The sampling rates of public bearing data sets whose files do not carry them.

When a file gives no rate and ``--fs`` is missing, the line that asks for ``--fs`` names the
rate the data set publishes where the file is laid out as that set's files are: its
variables' or columns' names (CWRU ``X097_DE_time``, Paderborn ``vibration_1``, XJTU-SY
``Horizontal_vibration_signals``) or its name (the IMS rig's ``2004.02.12.10.32.39``). The
rate is never taken from the match alone: a look-alike of another logger gets the same line.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["rate_hint"]

#: (a column's or variable's name, what the data set publishes)
_BY_COLUMN = (
    (re.compile(r"(X\d+_)?(DE|FE|BA)_time", re.IGNORECASE),
     "named as the CWRU bearing data centre's variables: --fs 12000 for its 12k data, --fs 48000 "
     "for its 48k data; the page the file came from says which"),
    (re.compile(r"(.*\.)?vibration_1(\.Data)?"),
     "named as the Paderborn bearing data centre's signals: --fs 64000, its vibration's and motor "
     "currents' rate; its speed, torque and force are sampled at 4000 Hz"),
    (re.compile(r"(Horizontal|Vertical)_vibration_signals"),
     "named as the XJTU-SY bearing data set's columns: --fs 25600, and --snapshot-interval 60 "
     "for its one file a minute"),
)
#: a file named by its date and time with dots, as the IMS rig's
_IMS_NAME = re.compile(r"\d{4}(\.\d{2}){5}")


def rate_hint(path: str, columns: list[str]) -> str:
    """`` (...)``: the rate a public data set publishes for files laid out as ``path`` and its
    ``columns``, or ``""``."""
    for pattern, said in _BY_COLUMN:
        if any(pattern.fullmatch(c) for c in columns):
            return f" ({said})"
    if _IMS_NAME.fullmatch(Path(path).name):
        return " (named as the IMS bearing rig's files: --fs 20480)"
    return ""
