"""WAV reader: PCM 8/16/24/32-bit and IEEE float, one column per WAV channel.

PCM samples are read as fractions of full scale (-1 .. 1): a 16-bit sample
divided by 2^15, 24- and 32-bit ones by 2^31 (scipy returns 24-bit samples
left-justified in int32), 8-bit unsigned ones as (x - 128) / 128. Float
samples are taken as they are. ``--scale-factor`` then gives the physical value
at full scale in ``--unit``. The file's sampling rate is the recording's.
"""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np

from .errors import ImportFailure
from .table import Table

__all__ = ["read_wav"]


def read_wav(path: str) -> Table:
    from scipy.io import wavfile  # 0.3 s to import: only when a WAV file is read

    try:
        with warnings.catch_warnings(record=True) as caught:   # unknown chunks are skipped silently
            warnings.simplefilter("always", wavfile.WavFileWarning)
            fs, a = wavfile.read(path, mmap=False)
    except (ValueError, EOFError, struct.error) as exc:
        why = "it ends inside its header" if isinstance(exc, struct.error) else " ".join(str(exc).split())
        raise ImportFailure(f"{path}: not a readable WAV file ({why}); export it as PCM or float WAV") from None
    if a.dtype == np.uint8:
        x = (a.astype(np.float64) - 128.0) / 128.0
    elif a.dtype == np.int16:
        x = a / 32768.0
    elif a.dtype == np.int32:
        x = a / 2147483648.0
    elif a.dtype.kind == "f":
        x = a
    else:  # pragma: no cover - scipy returns one of the above
        raise ImportFailure(f"{path}: WAV samples of type {a.dtype} are not supported; export as PCM 16/24/32 or float")
    if x.ndim == 1:
        x = x[:, None]
    if x.shape[0] == 0:
        raise ImportFailure(f"{path}: the WAV file holds no samples")
    names = [f"ch{i}" for i in range(x.shape[1])]
    cut = [" ".join(str(w.message).split()) for w in caught if "EOF" in str(w.message)]
    notes = [f"{Path(path).name}: the file ends before the data its header declares ({cut[0]}); the "
             f"{x.shape[0]:,} sample(s) there are imported"] if cut else []
    return Table(path=path, data=x[None], columns=names, kind="channel", fs=float(fs), notes=notes)
