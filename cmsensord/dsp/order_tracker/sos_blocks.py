"""The anti-alias cascade in numpy, block by block: scipy.signal's sosfilt without scipy,
and with the decimator's every D-th output only.

The numpy fallback of the decimator (no compiled kernel) filters with this instead
of ``scipy.signal.sosfilt``, whose import alone costs ~70 MB of resident memory on
the daemon's path.  Each second-order section, in direct form II transposed
(y(n) = b0 x(n) + z0, z0' = b1 x(n) - a1 y(n) + z1, z1' = b2 x(n) - a2 y(n)), is
the state-space system z' = A z + B x, y = c z + b0 x with

    A = [[-a1, 1], [-a2, 0]],  B = (b1 - a1 b0, b2 - a2 b0),  c = (1, 0),

and the cascade of S sections is one system of 2S states (the sections' states
stacked, scipy's layout; the series connection makes its A block lower-triangular).
Over a block of M samples the outputs are a lower-triangular Toeplitz matrix of the
cascade's impulse response times the block's inputs plus C A^k times the state at
the block's start, and the state at its end is A^M z plus a 2S x M matrix times the
inputs.  Only the rows of the outputs the decimator keeps (every D-th, M a multiple
of D) are formed: per block two matrix products for the whole cascade, and a
recursion over blocks (not samples) for the state.  Same results as sosfilt to
rounding (~1e-15 relative, tests/test_sos_blocks.py).
"""

from __future__ import annotations

import math

import numpy as np

#: about this many samples per block (rounded up to a multiple of the decimation)
BLOCK = 512


def _cascade(sos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A (2S, 2S), B (2S,), C (2S,), D) of the sections in series (module docstring)."""
    A = np.zeros((0, 0))
    B = np.zeros(0)
    C = np.zeros(0)
    D = 1.0
    for row in np.asarray(sos, dtype=np.float64):
        b0, b1, b2, _, a1, a2 = (float(v) for v in row / row[3])
        As = np.array([[-a1, 1.0], [-a2, 0.0]])
        Bs = np.array([b1 - a1 * b0, b2 - a2 * b0])
        n = len(B)
        An = np.zeros((n + 2, n + 2))
        An[:n, :n] = A
        An[n:, :n] = np.outer(Bs, C)              # the section's input is the cascade's output
        An[n:, n:] = As
        A, B = An, np.concatenate([B, Bs * D])
        C = np.concatenate([b0 * C, [1.0, 0.0]])
        D = b0 * D
    return A, B, C, D


class SosBlocks:
    """A cascade of second-order sections (rows b0 b1 b2 a0 a1 a2) run block by block,
    keeping every ``decimate``-th output (those at multiples of D from the stream's
    first sample).

    Blocks of M samples (``block`` rounded up to a multiple of D) are aligned to the
    stream's first sample: the state carried between calls is the cascade's state at
    the start of the current block (scipy's (S, 2, C) layout) and that block's inputs
    so far (``part``); every output is one row of the same products however the stream
    was cut into calls, so any cut gives the same bits (tests/test_sos_blocks.py).
    """

    def __init__(self, sos: np.ndarray, decimate: int = 1, block: int = BLOCK):
        self.D = int(decimate)
        self.M = self.D * max(1, math.ceil(int(block) / self.D))
        A, B, C, D = _cascade(sos)
        self.S = A.shape[0] // 2
        M = self.M
        AkB = np.empty((M, 2 * self.S))                # A^k B, k = 0..M-1
        CAk = np.empty((M, 2 * self.S))                # C A^k
        v, w = B.copy(), C.copy()
        for k in range(M):
            AkB[k], CAk[k] = v, w
            v, w = A @ v, w @ A
        self.A_M = np.linalg.matrix_power(A, M)        # the state over a whole block
        h = np.concatenate([[D], CAk[:M - 1] @ B])     # impulse response h(0..M-1)
        rows = np.arange(0, M, self.D)
        lag = rows[:, None] - np.arange(M)[None, :]
        self.toeplitz = np.where(lag >= 0, h[np.clip(lag, 0, M - 1)], 0.0)   # (M/D, M)
        self.obs = CAk[rows]                           # (M/D, 2S): C A^r at the kept rows r
        self.ctrl = np.ascontiguousarray(AkB[::-1].T)  # (2S, M): A^(M-1-k) B

    def _blocks(self, xb: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Blocks xb (nb, M, C) from the state z (2S, C): the kept outputs (nb, M/D, C) and
        the state after them.  Every block is the same products of the same shapes and the
        state steps block by block, so any grouping of the blocks into calls gives the
        same bits."""
        nb, C = xb.shape[0], xb.shape[2]
        drive = self.ctrl @ xb                         # (nb, 2S, C)
        Z = np.empty((nb + 1, 2 * self.S, C))              # the state at each block's start
        Z[0] = z
        A_M = self.A_M
        rows = list(Z)                                 # views, made once
        for d, cur, nxt in zip(drive, rows, rows[1:]):
            np.add(A_M @ cur, d, out=nxt)
        return self.toeplitz @ xb + self.obs @ Z[:nb], Z[nb].copy()

    def __call__(self, x: np.ndarray, zi: np.ndarray, part: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x (T, C) after the inputs ``part`` of the current block, from the block-start
        states zi (S, 2, C): (y, the new block-start states, the new ``part``), y the
        outputs at the inputs of x whose index from the block's start is a multiple of D.
        With D = 1, part empty and T a multiple of the block, scipy.signal.sosfilt(sos, x,
        axis=0, zi=zi)'s (y, zf) to rounding."""
        x = np.asarray(x, dtype=np.float64)
        C = x.shape[1]
        p = 0 if part is None else len(part)
        xx = x if not p else np.concatenate([part, x])
        M, D = self.M, self.D
        nb = len(xx) // M
        n = nb * M
        z = np.asarray(zi, dtype=np.float64).reshape(2 * self.S, C)
        y, z = self._blocks(xx[:n].reshape(nb, M, C), z)
        y = y.reshape(nb * (M // D), C)
        rest = len(xx) - n
        if rest:                                       # the current block's first rows, its
            pad = np.zeros((1, M, C))                  # missing inputs zero (they reach none)
            pad[0, :rest] = xx[n:]
            y_rest = (self.toeplitz @ pad + self.obs @ z[None])[0, :-(-rest // D)]
            y = np.concatenate([y, y_rest])
        zf = np.ascontiguousarray(z.reshape(self.S, 2, C))
        return y[-(-p // D):], zf, xx[n:].copy()
