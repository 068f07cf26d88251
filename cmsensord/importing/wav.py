"""WAV reader: PCM 8/16/24/32-bit and IEEE float, one column per WAV channel.

PCM samples are read as fractions of full scale (-1 .. 1): a 16-bit sample
divided by 2^15, 24- and 32-bit ones by 2^31 (scipy returns 24-bit samples
left-justified in int32), 8-bit unsigned ones as (x - 128) / 128. Float
samples are taken as they are. The samples stay in the file (a memory map)
and the import converts them a stretch at a time, so a long WAV does not
need its float64 copy in memory. ``--scale-factor`` then gives the physical value
at full scale in ``--unit``. The file's sampling rate is the recording's.
"""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

from .errors import ImportFailure
from .table import Table

__all__ = ["read_wav"]


def read_wav(path: str) -> Table:
    """The WAV file's samples as a memory map of the file where scipy can map it (8, 16, 32-bit
    PCM and float; a 24-bit or cut-short file is read), the PCM's scale as ``gain``/``zero``."""
    from scipy.io import wavfile  # 0.3 s to import: only when a WAV file is read

    try:
        cut = _chunks(path)
        with warnings.catch_warnings():   # unknown chunks are skipped silently; a short file: _chunks says so
            warnings.simplefilter("ignore", wavfile.WavFileWarning)
            fs, a = _read(wavfile, path)
    except (ValueError, EOFError, struct.error, ArithmeticError, UnboundLocalError) as exc:
        why = ("it ends inside its header" if isinstance(exc, struct.error) else
               "its header does not add up" if isinstance(exc, (ArithmeticError, UnboundLocalError)) else
               " ".join(str(exc).split()))
        raise ImportFailure(f"{path}: not a readable WAV file ({why}); export it as PCM or float WAV") from None
    zero, gain = (0.0, 1.0) if a.dtype.kind == "f" else _SCALES.get(a.dtype.str[1:], (None, None))
    if zero is None or gain is None:     # pragma: no cover - scipy returns one of the above
        raise ImportFailure(f"{path}: WAV samples of type {a.dtype} are not supported; export as PCM 16/24/32 or float")
    if a.ndim == 1:
        a = a[:, None]
    if a.shape[0] == 0:
        raise ImportFailure(f"{path}: the WAV file holds no samples")
    names = [f"ch{i}" for i in range(a.shape[1])]
    notes = [f"{Path(path).name}: the file ends before the data its header declares ({cut}); the "
             f"{a.shape[0]:,} sample(s) there are imported"] if cut else []
    return Table(path=path, data=a[None], columns=names, kind="channel", fs=float(fs), notes=notes,
                 gain=gain, zero=zero)


#: PCM sample type -> (zero, gain) to fractions of full scale (24-bit samples come left-justified in int32)
_SCALES = {"u1": (128.0, 1 / 128), "i2": (0.0, 1 / 32768), "i4": (0.0, 1 / 2147483648)}


def _chunks(path: str) -> str | None:
    """Walk the file's RIFF chunks up to its data chunk: a ValueError when a chunk runs past
    the end of the file or the ``fmt `` chunk names no channels or no bytes a sample frame
    (no samples could be read); what the data chunk declares against what is there when the
    file ends before it (else None)."""
    size = Path(path).stat().st_size
    with open(path, "rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] != b"RIFF" or head[8:] != b"WAVE":
            return None                 # scipy reads (or says what it is not) the others
        pos = 12
        while pos + 8 <= size:
            f.seek(pos)
            cid, n = struct.unpack("<4sI", f.read(8))
            name = cid.decode("latin-1").strip()
            if cid == b"data":
                there = size - pos - 8
                return f"its data chunk declares {n:,} bytes, {there:,} are there" if n > there else None
            if pos + 8 + n > size:
                raise ValueError(f"its {name} chunk declares {n:,} bytes, past the end of the file")
            if cid == b"fmt " and n >= 16:
                channels, align = struct.unpack("<2xH8xH", f.read(14))
                if not channels or not align:
                    what = "0 channels" if not channels else "a block align of 0 bytes"
                    raise ValueError(f"its fmt chunk gives {what}")
            pos += 8 + n + (n & 1)
    return None


def _read(wavfile, path: str):
    """(fs, samples): a memory map of the file's samples, or (24-bit, or a file cut short, which
    cannot be mapped) the samples read."""
    try:
        return wavfile.read(path, mmap=True)
    except ValueError:
        return wavfile.read(path, mmap=False)
