"""The MQTT queue's sequence numbers leased ahead on disk, so that no run gives a seq a
message was already sent under to another message.

A message may be sent before its record is durable (from the page cache, or from memory while
the disk refuses it), so what the queue's segments hold after a power cut or a stop on a
refusing disk says too little of the seqs already used. File ``seq-lease`` in the queue's
directory holds a seq N: no seq above N has been used. Before the queue numbers a message
above N, N is moved :data:`LEASE` ahead and written durably (a temporary file, fsync, rename,
fsync of the directory: :meth:`SeqLease.cover`); a run starts above N. A clean stop writes N
back down to the last seq used (:meth:`SeqLease.close`), so numbering goes on without a gap;
after a crash the next run starts above the lease, and a subscriber sees a gap of up to
:data:`LEASE` seqs, no reuse. While the disk refuses the write, seqs above N are used all the
same (the messages matter more than their numbers): such seqs may be used again after a crash.
"""

from __future__ import annotations

import os
from pathlib import Path

from cmsensord.sinks.mcap_file import fsync_dir

#: how far ahead of use the lease is written (one durable write per this many messages)
LEASE = 1 << 14


class SeqLease:
    """The lease of ``directory`` (:data:`upto`: 0 when it has none or it cannot be read)."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / "seq-lease"
        self.upto = self._read()
        self.error: OSError | None = None       # why the last write failed (None: written)

    def _read(self) -> int:
        try:
            text = self.path.read_text(encoding="ascii").strip()
        except (OSError, ValueError):
            return 0
        return int(text) if text.isdigit() and int(text) < 1 << 63 else 0    # beyond a u64 seq: garbage

    def cover(self, seq: int) -> None:
        """Seqs up to ``seq`` leased durably before it is sent: the lease moved :data:`LEASE`
        past it when ``seq`` is beyond it (a refusing disk: :attr:`error`, tried again with the
        next seq)."""
        if seq <= self.upto:
            return
        try:
            self._write(seq - 1 + LEASE)
        except OSError as err:
            self.error = err
            return
        self.upto, self.error = seq - 1 + LEASE, None

    def close(self, next_seq: int) -> None:
        """A clean stop: the lease brought down to the last seq used, so the next run numbers
        on from ``next_seq`` (a refusing disk keeps the lease as it is: the next run starts above)."""
        try:
            self._write(next_seq - 1)
        except OSError:
            return
        self.upto = next_seq - 1

    def _write(self, upto: int) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w", encoding="ascii") as f:
            f.write(f"{upto}\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)
        fsync_dir(self.path.parent)
