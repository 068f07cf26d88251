"""What a calibration on top of an earlier site file (``--config BASE.yaml``) changes: the lines
``cmsensord calibrate`` prints so a re-commissioning does not replace a machine's baselines,
or leave a channel of the capture out, without a word.

* :func:`unlisted_channels`: the capture's board channels BASE does not list (calibrate learns
  only the listed ones, so the new site file does not monitor the others).
* :func:`replaced_baselines`: each channel's ``baseline`` and the ``alarms.baselines`` values
  that the new file replaces, old -> new with their ratio.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ["unlisted_channels", "replaced_baselines"]

#: a baseline changing by less than this share is not said (a recalibration on similar data)
SAME_WITHIN = 0.01


def unlisted_channels(listed: Sequence[tuple[str, int]], board_channels: int, capture: str, base_path: str,
                      out: str) -> str:
    """The warning on the board channels (indices below ``board_channels``) that none of BASE's
    ``listed`` (name, index) channels reads ("" when BASE lists them all)."""
    taken = {index for _, index in listed}
    unlisted = [i for i in range(board_channels) if i not in taken]
    if not unlisted:
        return ""
    which = ", ".join(str(i) for i in unlisted)
    return (f"warning: {capture} has {board_channels} channel(s); {base_path} lists {len(listed)} "
            f"({', '.join(f'{n} (index {i})' for n, i in listed)}): channel index(es) {which} not learned, and "
            f"left out of {out}: add them to {base_path}'s channels (name, index) to monitor them")


def _ratio(old: float, new: float) -> str:
    return f"x{new / old:.3g}" if old > 0 else "from 0"


def _changed(old: Any, new: float) -> bool:
    if not isinstance(old, (int, float)) or isinstance(old, bool):
        return False
    return abs(new - old) > SAME_WITHIN * max(abs(old), abs(new))


def replaced_baselines(base: Any, learned: Sequence[tuple[str, float]], baselines: Sequence[dict[str, Any]],
                       out: str) -> list[str]:
    """A note per channel whose BASE ``baseline`` the ``learned`` (name, baseline) one replaces,
    and one on the ``alarms.baselines`` values replaced (``baselines``: the new rows), the
    largest change named."""
    if not isinstance(base, dict):
        return []
    lines = []
    old_ch = {ch.get("name"): ch for ch in base.get("channels") or [] if isinstance(ch, dict)}
    for name, new in learned:
        old: Any = old_ch.get(name, {}).get("baseline")
        if _changed(old, new):
            lines.append(f"note: {out}: {name} baseline {old:.4g} -> {new:.4g} ({_ratio(float(old), new)}) "
                         "replaces BASE's")
    alarms = base.get("alarms")
    rows = alarms.get("baselines") if isinstance(alarms, dict) else None
    old_rows: dict[tuple[Any, Any], Any] = {(b.get("channel"), b.get("indicator")): b.get("value")
                                            for b in rows or [] if isinstance(b, dict)}
    changed = [(k, float(old_rows[k]), float(row["value"])) for row in baselines
               if _changed(old_rows.get(k := (row["channel"], row["indicator"])), row["value"])]
    if changed:
        (ch, name), was, now = max(changed, key=lambda c: max(c[1], c[2]) / max(min(c[1], c[2]), 1e-300))
        lines.append(f"note: {out}: {len(changed)} of BASE's {len(old_rows)} alarms.baselines value(s) replaced; "
                     f"the largest change {name} on {ch} {was:.4g} -> {now:.4g} ({_ratio(was, now)})")
    return lines
