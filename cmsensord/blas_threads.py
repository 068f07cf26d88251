"""One BLAS thread in every process of cmsensord and of its simulated board.

numpy's OpenBLAS starts a worker thread per core at its import and, after a matrix
product large enough to split, keeps them spinning for a while in wait for the next
one.  The simulated board's products (a scenario's (2H, L) envelopes, every block)
made ``cmsensord --simulate`` use 34 s of CPU in its 30 s, nine times what one
thread takes for the same numbers, and ``firmware_sim --pty`` at 1x ~11 % of a core
instead of ~1 %, on the machine the daemon it feeds is measured on.  The daemon's
own matrices are small and its work is one stream, so on a board it gains nothing
from them either; with one thread the products are also summed in one order.

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
