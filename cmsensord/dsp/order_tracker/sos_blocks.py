"""The anti-alias cascade in numpy, block by block: scipy.signal.sosfilt without scipy.

The numpy fallback of the decimator (no compiled kernel) filters with this instead
of ``scipy.signal.sosfilt``, whose import alone costs ~70 MB of resident memory on
the daemon's path.  Each second-order section, in direct form II transposed
(y(n) = b0 x(n) + z0, z0' = b1 x(n) - a1 y(n) + z1, z1' = b2 x(n) - a2 y(n)), is
the state-space system z' = A z + B x, y = c z + b0 x with

    A = [[-a1, 1], [-a2, 0]],  B = (b1 - a1 b0, b2 - a2 b0),  c = (1, 0).

Over a block of M samples the outputs are a lower-triangular Toeplitz matrix of the
impulse response times the block's inputs plus c A^k times the state at the block's
start, and the state at its end is A^M z plus a 2 x M matrix times the inputs:
matrix products for all the blocks of a call, and a recursion over blocks (not
samples) for the states.  Same results as sosfilt to rounding (~1e-15 relative,
tests/test_sos_blocks.py).
"""

from __future__ import annotations

import numpy as np

#: samples per block of the block recursion
BLOCK = 64


class _Section:
    """The block matrices of one section (module docstring)."""

    def __init__(self, row: np.ndarray, M: int):
        b0, b1, b2, _, a1, a2 = (float(v) for v in row / row[3])
        A = np.array([[-a1, 1.0], [-a2, 0.0]])
        B = np.array([b1 - a1 * b0, b2 - a2 * b0])
        powers = [np.eye(2)]
        for _ in range(M):
            powers.append(A @ powers[-1])
        self.A_pow = np.stack(powers)                        # (M + 1, 2, 2): A^k
        self.obs = self.A_pow[:M, 0, :]                      # (M, 2): c A^k
        h = np.empty(M)
        h[0] = b0
        h[1:] = self.A_pow[:M - 1, 0, :] @ B                 # c A^(j-1) B
        idx = np.arange(M)
        lag = idx[:, None] - idx[None, :]
        self.toeplitz = np.where(lag >= 0, h[np.clip(lag, 0, M - 1)], 0.0)   # (M, M)
        self.ctrl = (self.A_pow[M - 1::-1] @ B).T            # (2, M): A^(M-1-k) B
        self.M = M

    def blocks(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whole blocks x (nb M, C) from the state z (2, C): y, the state after them.  Every
        block is one product of the same shapes and the state steps block by block, so any
        grouping of the blocks into calls gives the same bits."""
        M = self.M
        nb, C = x.shape[0] // M, x.shape[1]
        xb = x.reshape(nb, M, C)
        drive = self.ctrl @ xb                               # (nb, 2, C)
        S = np.empty((nb, 2, C))
        A_M = self.A_pow[M]
        for b in range(nb):
            S[b] = z
            z = A_M @ z + drive[b]
        return (self.toeplitz @ xb + self.obs @ S).reshape(nb * M, C), z

    def partial(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The outputs of the first len(x) < M samples of a block from its start state z:
        the block's products with the missing inputs zero (they do not reach these rows)."""
        pad = np.zeros((1, self.M, x.shape[1]))
        pad[0, :len(x)] = x
        return (self.toeplitz @ pad + self.obs @ z[None])[0, :len(x)]


class SosBlocks:
    """A cascade of second-order sections (rows b0 b1 b2 a0 a1 a2) run block by block.

    Blocks are aligned to the stream's first sample: the state carried between calls is
    each section's state at the start of the current block (scipy's (S, 2, C) layout)
    and that block's inputs so far (``part``), so every output is computed the same way
    however the stream was cut into calls (tests/test_sos_blocks.py).
    """

    def __init__(self, sos: np.ndarray, block: int = BLOCK):
        self.M = int(block)
        self.sections = [_Section(np.asarray(row, dtype=np.float64), self.M) for row in sos]

    def __call__(self, x: np.ndarray, zi: np.ndarray, part: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x (T, C) after the inputs ``part`` of the current block, from the block-start
        states zi (S, 2, C): (y (T, C), the new block-start states, the new ``part``).
        With part empty and T a multiple of BLOCK, scipy.signal.sosfilt(sos, x, axis=0,
        zi=zi)'s (y, zf) to rounding."""
        x = np.asarray(x, dtype=np.float64)
        p = 0 if part is None else len(part)
        xx = x if not p else np.concatenate([part, x])
        n = len(xx) // self.M * self.M
        zf = np.empty_like(zi)
        y_full, y_rest = xx[:n], xx[n:]
        for s, sec in enumerate(self.sections):
            y_full, zf[s] = sec.blocks(y_full, zi[s])
            if len(y_rest):
                y_rest = sec.partial(y_rest, zf[s])
        return np.concatenate([y_full, y_rest])[p:], zf, xx[n:].copy()
