"""``cmsensord import``: recordings from other data loggers turned into captures.

A capture of the board's serial protocol (docs/PROTOCOL.md) is the one input
``replay`` and everything downstream read; this package writes one from a WAV,
CSV/TSV, NPY/NPZ, MATLAB v5/v7 or TDMS file, or from a directory or glob of snapshot
files, plus a sidecar JSON (``CAPTURE.json``, e.g. ``b11.bin.json``) that records where every snapshot
came from and the gaps between them.

Modules, one job each:

* :mod:`.errors` -- the one-line :class:`ImportFailure`;
* :mod:`.options` -- the settings the user asked for;
* :mod:`.table` -- what every reader returns (raw columns, maybe fs, times, rpm);
* :mod:`.wav`, :mod:`.tabular`, :mod:`.arrays`, :mod:`.matlab`, :mod:`.tdms` -- the readers;
* :mod:`.text_head` -- where a text table's numbers begin (comments, a preamble, the names);
* :mod:`.preamble` -- the start date and time a text table's preamble gives (LabVIEW's);
* :mod:`.time_column` -- a text table's column of times: the rate, and no channel;
* :mod:`.variables` -- which arrays or variables of an archive are the data, side by side;
* :mod:`.sources` -- SRC arguments to files in order, files to a :class:`Recording`;
* :mod:`.snapshot_times` -- the snapshots' times in the original recording;
* :mod:`.name_times` -- the dates and times in snapshot files' names;
* :mod:`.channel_names` -- channel names from the columns' labels (letters, digits and ``_``);
* :mod:`.recording` -- the recording (m/s², snapshots, tacho edges);
* :mod:`.samples` -- its samples, in memory up to ``--memory-mb``, beyond it on disk;
* :mod:`.units` -- the input units to m/s² (a microphone's: Pa);
* :mod:`.adc` -- the 12-bit full-scale range and the counts;
* :mod:`.tacho` -- tacho edges from a pulse column, a speed column or a constant speed;
* :mod:`.blocks` -- block length, which samples fill blocks, the board clock;
* :mod:`.capture_writer` -- frames to ``OUT.part``, the sidecar, the rename;
* :mod:`.sidecar` -- the sidecar read back (replay, calibrate, vkf, the acoustic calibration);
* :mod:`.command` -- the argparse sub-command and its summary;
* :mod:`.timeline` -- board seconds of a capture to times in the recording, or to its share of
  it (replay, report).
"""

from .errors import ImportFailure
from .recording import Recording, Snapshot

__all__ = ["ImportFailure", "Recording", "Snapshot"]
