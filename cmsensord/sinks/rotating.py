"""A sink that rotates MCAP files by time and size and fsyncs them on a schedule.

Owns the policy of ``output`` in the configuration (flush_s, fsync_s,
rotate_s, rotate_mb); each file is an :class:`~cmsensord.sinks.mcap_sink.McapSink`
(written as ``*.mcap.part``, renamed to ``*.mcap`` when finished).  Rotation
happens between messages, so no message is split across files.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from cmsensord.config import OutputConfig
from cmsensord.sinks.mcap_sink import McapSink


class RotatingSink:
    """``write``/``flush``/``close`` like McapSink, over a sequence of files."""

    def __init__(self, output: OutputConfig, *, metadata: dict[str, str] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 on_rotate: Callable[[Path], None] | None = None):
        self.output = output
        self.metadata = metadata or {}
        self.clock = clock
        self.on_rotate = on_rotate
        self.paths: list[Path] = []          # finished files, oldest first
        self._rotate_bytes = int(output.rotate_mb * 1e6)
        self._current = self._open()
        self._last_sync = clock()
        self.messages_written = 0

    def _open(self) -> McapSink:
        o = self.output
        sink = McapSink(o.dir, prefix=o.prefix, compression=o.compression, flush_s=o.flush_s,
                        clock=self.clock, metadata=self.metadata)
        self._opened = self.clock()
        return sink

    @property
    def path(self) -> Path:
        """The file being written (its final name)."""
        return self._current.path

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        self._current.write(topic, schema, stamp_ns, msg)
        self.messages_written += 1
        if (self.clock() - self._opened >= self.output.rotate_s
                or self._current.bytes_written >= self._rotate_bytes):
            self.rotate()

    def rotate(self) -> Path:
        """Finish the current file and start the next; returns the finished path."""
        done = self._current.close()
        self.paths.append(done)
        self._current = self._open()
        self._last_sync = self.clock()
        if self.on_rotate is not None:
            self.on_rotate(done)
        return done

    def flush(self) -> None:
        """Write the open chunk; fsync when fsync_s has passed since the last one."""
        now = self.clock()
        if now - self._last_sync >= self.output.fsync_s:
            self._current.sync()
            self._last_sync = now
        else:
            self._current.flush()

    def close(self) -> Path:
        """Finish the current file; returns its path (all files are in ``paths``)."""
        done = self._current.close()
        if not self.paths or self.paths[-1] != done:
            self.paths.append(done)
        return done
