"""One BLAS thread in every process of cmsensord and of its simulated board.

numpy's (and scipy's) OpenBLAS starts a worker thread per further core at its import
and, after a matrix product large enough to split, keeps the workers spinning for a
while in wait for the next one.  The daemon's matrices are small and its work is one
stream, and the simulated board's products are a few per block: the workers add CPU
(on the board, beside the daemon), not speed (README, "Dependencies", has the figures).

Importing this module sets ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and
``MKL_NUM_THREADS`` to 1 where the environment does not set them (a value given
there is kept).  They act only before numpy's first import in the process, so
``cmsensord/__init__`` and ``firmware_sim/__init__`` import this module first; the
processes they start inherit them.
"""

from __future__ import annotations

import os

#: the variables that bound the BLAS libraries numpy may be built with (OpenBLAS, OpenMP, MKL)
LIMITS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

for _name in LIMITS:
    os.environ.setdefault(_name, "1")
