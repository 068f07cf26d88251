"""Where a capture stops being one board set-up, for the offline tools that treat a whole
capture as one record (the batch VKF, the acoustic calibration): the first STATUS, and the
first later STATUS that changes what :data:`FIELDS` names, or the first data frame whose t0
goes back (the board restarted its clock).  The daemon follows such changes; these tools
cannot, so they stop with one line that says what changed and at which byte."""

from __future__ import annotations

import contextlib

from cmsensord.protocol import SETUP_FIELDS, Frame, FrameType, Status, decode_status

#: what a STATUS may change that one record cannot follow
FIELDS = (*SETUP_FIELDS, "scale", "offset")


class OneSetup:
    """Watches a capture's frames in order (:meth:`see`): :attr:`status` is its first good
    STATUS, :attr:`changed` what first broke the one set-up (None while nothing has)."""

    def __init__(self) -> None:
        self.status: Status | None = None
        self.changed: str | None = None
        self._newest_t0 = -1

    def see(self, f: Frame) -> None:
        """One frame of the capture, in order."""
        if self.changed is not None:
            return
        if f.type == FrameType.STATUS:
            with contextlib.suppress(ValueError):
                self._status(decode_status(f.payload), f.offset)
            return
        if f.t0_unwrapped < self._newest_t0:
            self.changed = f"restarted its clock (t0 {f.t0_unwrapped} after {self._newest_t0}) at byte {f.offset}"
        self._newest_t0 = f.t0_unwrapped

    def _status(self, st: Status, offset: int) -> None:
        if self.status is None:
            self.status = st
            return
        moved = [k for k in FIELDS if getattr(st, k) != getattr(self.status, k)]
        if moved:
            self.changed = f"changed its {', '.join(moved)} at byte {offset}"
