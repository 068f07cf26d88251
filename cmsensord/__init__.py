"""cmsensord: condition-monitoring daemon for rotating machines.

Rooms: ``protocol`` (wire format), ``dsp`` (AKF bank, severity), ``pipeline``
(per-channel state, the real-time loop), ``link`` (serial port, capture files),
``sinks`` (MCAP), ``config``, ``cli``.
"""

from cmsensord import blas_threads  # noqa: F401  (before numpy: one BLAS thread)

__version__ = "0.1.0"
