"""MCAP sink: JSON messages with jsonschema schemas into one crash-safe MCAP file.

The public interface of the MCAP output, gathered from the modules that own
each part (schemas and topics in :mod:`cmsensord.sinks.schemas`):

* :mod:`~cmsensord.sinks.mcap_encoding`: message encoding (compact JSON,
  NaN and infinity as ``null``, the ``timestamp`` field) and the lazy
  registration of schemas and channels; :func:`ns_to_stamp`;
* :mod:`~cmsensord.sinks.mcap_chunks`: the MCAP records and the chunk writer;
* :mod:`~cmsensord.sinks.mcap_file`: :class:`McapSink`, the crash-safe
  ``.part`` file renamed when finished, :class:`SinkIOError`, and the file
  names (:func:`log_files`, :func:`salvaged_path`);
* :mod:`~cmsensord.sinks.mcap_salvage`: :func:`salvage` of a leftover
  ``.part`` file, :func:`salvage_leftovers`, :class:`SalvageResult`;
* :mod:`~cmsensord.sinks.mcap_read`: the record walker, :func:`summarize`,
  :func:`read_messages`, :func:`iter_messages_lenient`, :data:`NOT_MCAP`.

Rotation, periodic fsync, retention and disk-error policy are
:class:`~cmsensord.sinks.rotating.RotatingSink`'s.
"""

from __future__ import annotations

from cmsensord.sinks.mcap_encoding import ns_to_stamp
from cmsensord.sinks.mcap_file import McapSink, SinkIOError, log_files, salvaged_path
from cmsensord.sinks.mcap_read import NOT_MCAP, iter_messages_lenient, read_messages, summarize
from cmsensord.sinks.mcap_salvage import SalvageResult, salvage, salvage_leftovers

__all__ = [
    "McapSink",
    "SinkIOError",
    "SalvageResult",
    "ns_to_stamp",
    "read_messages",
    "summarize",
    "iter_messages_lenient",
    "salvage",
    "salvage_leftovers",
    "salvaged_path",
    "log_files",
    "NOT_MCAP",
]
