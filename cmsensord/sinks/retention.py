"""Retention of a rotating sink's finished log files: size cap and free-space floor.

The ``.part`` files salvage kept (``*.mcap.part.damaged``, ``*.mcap.part.unreadable``) count as
finished files of their name's time: in ``retain_mb``, and deleted oldest first as logs are
(they were kept for a human, not forever: outside retention they took the logs' room)."""

from __future__ import annotations

import contextlib
import errno
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from cmsensord.sinks.mcap_file import fsync_dir, log_files

if TYPE_CHECKING:
    from cmsensord.sinks.rotating import RotatingSink

#: a pass each time the file being written grows by this share of ``retain_mb`` (so the prefix's
#: files, that file included, pass the cap by at most that share between rotations)
PASS_EVERY = 1 / 64
#: the kind of disk events (``details["action"]`` tells them apart): retention's refusals and a
#: floor out of reach among them
DISK_EVENT = "disk_error"
#: the kind of retention's routine deletions (INFO in the journal; ``details["action"]``
#: ``retention``): its own, so that they neither use up the journal's budget of ``disk_error``
#: lines nor stand among real disk errors
RETENTION_EVENT = "retention"
MB = 1_000_000

#: unlink errors of the file itself, not of its directory or file system: a directory under a
#: log's name (EISDIR), an immutable file or another user's in a sticky directory (EPERM), a
#: mount point or a running program (EBUSY, ETXTBSY). Retention passes over such a file to the
#: next oldest, and leaves it out of ``retain_mb``'s count; any other error (no write
#: permission on the directory, a read-only or failing file system) would refuse every file,
#: and ends the pass.
PASS_OVER = frozenset({errno.EISDIR, errno.EPERM, errno.EBUSY, errno.ETXTBSY})


@dataclass
class RetentionTold:
    """What retention has told and not repeated while it stays: the disk is low (``low_space``),
    and the files it cannot delete (``refused``: each file's path, with errno's name and the
    passes since its event that failed on it the same way)."""

    low_space: bool = False
    refused: dict[str, tuple[str | None, int]] = field(default_factory=dict)
    #: the next pass when the file being written holds this many bytes (:data:`PASS_EVERY` of the cap on)
    next_bytes: float = float("inf")

    def refuse(self, path: str, code: str | None) -> bool:
        """A pass failed on ``path`` with errno ``code``: True when that is news (to be told),
        else one repeat more."""
        told = self.refused.get(path)
        if told is not None and told[0] == code:
            self.refused[path] = (code, told[1] + 1)
            return False
        self.refused[path] = (code, 0)
        return True

    def passed(self, path: str) -> int:
        """A pass got past ``path`` (deleted, or gone): its refusal is over; the passes that
        repeated it (0: none, or never refused)."""
        return self.refused.pop(path, (None, 0))[1]

    def keep_only(self, paths: list[Path]) -> None:
        """Forget the refusals of files no longer among ``paths`` (gone meanwhile)."""
        names = {str(p) for p in paths}
        for path in [p for p in self.refused if p not in names]:
            del self.refused[path]


def errno_name(code: int | None) -> str | None:
    """errno's symbolic name (ENOSPC ...), None without a code."""
    return errno.errorcode.get(code, str(code)) if code is not None else None


def still_there(paths: list[Path]) -> list[Path]:
    """Those of ``paths`` still in their directory: a log moved away or deleted by another
    program (an archiver, an operator) is no longer one of the run's, so a daemon running for
    months holds no more of them than the directory does."""
    kept = []
    for path in paths:
        try:
            os.lstat(path)
        except FileNotFoundError:
            continue
        except OSError:
            pass                         # unreadable now (a failing disk): still counted
        kept.append(path)
    return kept


def free_bytes(path: str | Path) -> int:
    """Bytes free for an unprivileged writer on the file system of ``path``."""
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize


def _retained(sink: RotatingSink) -> set[Path] | None:
    """The files retention may count and delete: with the sink's ``own_files`` those its run
    wrote (finished, being written, kept for salvage); else None, every file of the prefix."""
    if not sink.own_files:
        return None
    cur = sink.current
    return {*sink.paths, *sink._abandoned, *([cur.part_path] if cur is not None else [])}


def apply_retention(sink: RotatingSink) -> None:
    """Delete the oldest finished files (and kept ``.part`` copies) while over ``retain_mb`` (the
    file being written counted: a pass runs each time it grows by :data:`PASS_EVERY` of the cap) or
    under ``min_free_mb``: of the prefix, or with the sink's ``own_files`` (a replay) of this run
    only, counting only its files (:func:`_retained`).

    Oldest: opened first, by the names' order (:mod:`cmsensord.sinks.log_names`), which a
    wall clock stepping back does not change.

    For ``min_free_mb`` the newest finished file is never deleted, and
    nothing is when deleting all the others could not reach it (the free
    space is taken by something else): a ``low_space`` event says so.
    """
    o = sink.output
    cap = o.retain_mb * MB if o.retain_mb else None
    floor = o.min_free_mb * MB if o.min_free_mb else None
    if cap is None and floor is None:
        return
    cur = sink.current
    sink.retention.next_bytes = (cur.bytes_written if cur is not None else 0) + max(
        16_384, (cap if cap is not None else floor or 0) * PASS_EVERY)
    try:
        finished, parts = log_files(o.dir, o.prefix, kept=True)
        free = free_bytes(o.dir) if floor is not None else 0
    except OSError:
        return                           # no directory yet, or unreadable: nothing to do
    own = _retained(sink)                # a replay's: its own files only, never the daemon's
    if own is not None:
        finished, parts = [p for p in finished if p in own], [p for p in parts if p in own]
    sizes = file_sizes(finished + parts)
    oldest = [p for p in finished if p in sizes]    # in the order they were opened (log_names)
    older = sum(sizes[p] for p in oldest[:-1])       # what the floor may delete
    told = sink.retention
    told.keep_only(oldest)
    deleted, total, free, repeats, kept = _delete_oldest(sink, oldest, sizes, cap, floor, free)
    if deleted:
        with contextlib.suppress(OSError):  # the deletions are done; durability of the names only
            fsync_dir(Path(o.dir))
        sink.paths = [p for p in sink.paths if p not in deleted]
        _deleted_event(sink, deleted, sum(sizes[p] for p in deleted), total, free, repeats,
                       (len(kept), sum(sizes[p] for p in kept)))
    low = floor is not None and free < floor
    if low and not told.low_space and not deleted:
        told.low_space = True
        sink.emit(DISK_EVENT, f"{o.dir}: {free / MB:.1f} MB free, below min_free_mb = "
                  f"{o.min_free_mb:g} MB, which deleting the {max(0, len(oldest) - 1)} older "
                  f"finished log(s) of {_whose(sink)} ({older / MB:.1f} MB; never the "
                  f"newest) cannot reach: none deleted for it",
                  details={"action": "low_space", "bytes": free})
    elif not low:
        told.low_space = False


def _whose(sink: RotatingSink) -> str:
    """Whose logs retention deletes: this run's (a replay's) or the prefix's."""
    return "this run" if sink.own_files else f"prefix {sink.output.prefix!r}"


def file_sizes(paths: list[Path]) -> dict[Path, int]:
    """The size of each of ``paths`` still there; a planted link's own, never its target's."""
    sizes = {}
    for path in paths:
        with contextlib.suppress(OSError):  # gone meanwhile
            sizes[path] = path.lstat().st_size
    return sizes


def _delete_oldest(sink: RotatingSink, oldest: list[Path], sizes: dict[Path, int], cap: float | None,
                   floor: float | None, free: int) -> tuple[list[Path], int, int, int, list[Path]]:
    """Delete ``oldest`` in order while over ``cap`` bytes in all or under ``floor`` bytes free
    (the floor only where deleting all but the newest reaches it, never the newest): the files
    deleted, the bytes left in all, the bytes free after, the most passes that repeated the
    refusal of a file it got past (:class:`RetentionTold`), and the files passed over. A file it cannot delete is a
    :func:`_refused` event; one refused for a reason of its own (:data:`PASS_OVER`) is passed
    over and left out of ``cap``'s count (else one large file would take every other log with
    it), and the floor's reach counted again without it; any other refusal ends it."""
    total = sum(sizes.values())
    reachable = _reaches(floor, free, oldest, sizes)
    deleted: list[Path] = []
    kept: list[Path] = []
    repeats = 0
    for k, path in enumerate(oldest):
        over = cap is not None and total > cap
        low = reachable and floor is not None and free < floor and path != oldest[-1]
        if not (over or low):
            break
        try:
            path.unlink()
        except FileNotFoundError:
            pass
        except OSError as err:
            _refused(sink, path, err)
            if err.errno not in PASS_OVER:
                break
            total -= sizes[path]             # kept on purpose: not the other logs' to make room for
            kept.append(path)
            reachable = reachable and _reaches(floor, free, oldest[k + 1:], sizes)
            continue
        repeats = max(repeats, sink.retention.passed(str(path)))
        total -= sizes[path]
        deleted.append(path)
        if floor is not None:
            try:
                free = free_bytes(sink.output.dir)
            except OSError:
                free += sizes[path]
    return deleted, total, free, repeats, kept


def _reaches(floor: float | None, free: int, oldest: list[Path], sizes: dict[Path, int]) -> bool:
    """Whether deleting all of ``oldest`` but the newest would bring ``free`` bytes up to ``floor``."""
    return floor is not None and free + sum(sizes[p] for p in oldest[:-1]) >= floor


def _refused(sink: RotatingSink, path: Path, err: OSError) -> None:
    """``path`` cannot be deleted: a ``retention_failed`` event, once while the same file fails
    the same way pass after pass (each failure counted in ``disk_errors``; the repeats in
    ``sink.retention``, told by the pass that gets past it)."""
    sink.disk_errors += 1
    code = errno_name(err.errno)
    if sink.retention.refuse(str(path), code):
        sink.emit(DISK_EVENT, f"{path}: retention cannot delete: {err.strerror or err}",
                  details={"action": "retention_failed", "errno": code, "file": str(path)})


def _deleted_event(sink: RotatingSink, deleted: list[Path], freed: int, total: int, free: int,
                   repeats: int = 0, kept: tuple[int, int] = (0, 0)) -> None:
    """The ``retention`` event (kind :data:`RETENTION_EVENT`) of the files ``deleted`` (``freed``
    bytes; ``total`` left, ``free``); ``repeats``: the passes that failed again as the last
    ``retention_failed`` event told; ``kept``: (files, bytes) passed over, which ``total`` leaves out."""
    o = sink.output
    why = []
    if o.retain_mb:
        besides = f", besides {kept[1] / MB:.1f} MB in {kept[0]} file(s) passed over" if kept[0] else ""
        why.append(f"{'this run' if sink.own_files else 'this prefix'}'s files under retain_mb = {o.retain_mb:g} MB "
                   f"(now {total / MB:.1f} MB{besides})")
    if o.min_free_mb:
        why.append(f"at least min_free_mb = {o.min_free_mb:g} MB free "
                   f"(now {free / MB:.1f} MB)")
    names = ", ".join(p.name for p in deleted[:3]) + (" ..." if len(deleted) > 3 else "")
    again = f"; the {repeats + 1} pass(es) before this one failed (told once)" if repeats else ""
    sink.emit(RETENTION_EVENT, f"deleted the {len(deleted)} oldest log file(s) "
              f"({freed / MB:.1f} MB: {names}) to keep {' and '.join(why)}{again}",
              count=len(deleted), details={"action": "retention",
                                           "files": [p.name for p in deleted],
                                           "bytes": freed})
