"""How long a rotating sink's reorder windows hold messages, from file to file.

Each file's :class:`~cmsensord.sinks.reorder.ReorderWindow` learns how late messages come, up
to :data:`~cmsensord.sinks.reorder.MAX_S` (10 s), and the horizon it learnt carries over to the
next file. A part of the chain that knows its messages will come late says so ahead
(:meth:`ReorderLag.expect_lag`: the order chain, captures), so the window holds that long from
then on instead of writing the first late ones with a clamped log time. An expectation opens the
window up to :attr:`ReorderLag.max_lag_s`: 10 s for the daemon, whose window a kill -9 loses, and
without a bound for a replay, whose window is then bounded by its memory alone (8 MB of messages,
200,000 of them: the oldest beyond are written). ``cmsensord vkf`` holds every message of a file
until its end (:meth:`ReorderLag.hold_all`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cmsensord.sinks.reorder import MAX_S

if TYPE_CHECKING:
    from cmsensord.sinks.mcap_file import McapSink

__all__ = ["ReorderLag"]


class ReorderLag:
    """The reorder windows' horizon over the files of a sink (a base of
    :class:`~cmsensord.sinks.rotating.RotatingSink`): ``_current`` is the file being written."""

    _current: McapSink | None
    #: the longest lag an expectation opens a window to [s]
    max_lag_s: float = MAX_S
    _horizon_ns = 0                 # the windows' horizon, carried to the next file
    _hold_all = False

    def expect_lag(self, seconds: float = MAX_S) -> None:
        """Messages will come up to ``seconds`` late (at most :attr:`max_lag_s`): the reorder
        window holds that long from now on, instead of learning it from the first late messages
        (which it would write with a clamped log time)."""
        self._horizon_ns = max(self._horizon_ns, int(min(seconds, self.max_lag_s) * 1e9))
        if self._current is not None:
            window = self._current.reorder
            window.max_ns = max(window.max_ns, self._horizon_ns)
            window.horizon_ns = max(window.horizon_ns, self._horizon_ns)

    def hold_all(self) -> None:
        """Every message is held until its file is finished (at most 200,000, then the oldest
        go): ``cmsensord vkf`` writes the batch orders of the whole run after it, in order."""
        self._hold_all = True
        if self._current is not None:
            self._current.reorder.hold_all()

    def _window_of(self, sink: McapSink) -> McapSink:
        """A new file's window: the horizon carried over (beyond 10 s when expected), or all held."""
        sink.reorder.max_ns = max(sink.reorder.max_ns, self._horizon_ns)
        sink.reorder.horizon_ns = self._horizon_ns
        if self._hold_all:
            sink.reorder.hold_all()
        return sink
