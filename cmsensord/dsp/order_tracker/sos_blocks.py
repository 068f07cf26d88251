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
matrix products for up to MAX_BLOCKS blocks at once, the states at the blocks'
starts included (one matrix of powers of A^M).  Same results as sosfilt to rounding (~1e-15 relative,
compared in tests/test_order_tracker.py), the state carried between calls in
scipy's layout (S, 2, C).
"""

from __future__ import annotations

import numpy as np

#: samples per block of the block recursion
BLOCK = 64
#: most blocks chained in one matrix product (bounds the cached (2n x 2n) matrices)
MAX_BLOCKS = 64


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
        self._links: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _chain(self, nb: int) -> tuple[np.ndarray, np.ndarray]:
        """The states at the starts of nb blocks from the state z0 and the blocks' drives
        d_j: z_b = (A^M)^b z0 + sum_{j<b} (A^M)^(b-1-j) d_j, as (2nb x 2) and (2nb x 2nb)
        matrices (cached per nb)."""
        got = self._links.get(nb)
        if got is None:
            Q = [np.eye(2)]
            for _ in range(nb):
                Q.append(self.A_pow[self.M] @ Q[-1])
            from_z = np.concatenate(Q[:nb])                  # (2nb, 2)
            W = np.zeros((nb, 2, nb, 2))
            for b in range(1, nb):
                for j in range(b):
                    W[b, :, j, :] = Q[b - 1 - j]
            got = self._links[nb] = (from_z, W.reshape(2 * nb, 2 * nb))
        return got

    def run(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x (T, C) with the state z (2, C) -> y (T, C), the final state."""
        M = self.M
        T, C = x.shape
        y = np.empty_like(x)
        done = 0
        while T - done >= M:
            nb = min((T - done) // M, MAX_BLOCKS)
            end = done + nb * M
            X = x[done:end].reshape(nb, M, C).transpose(1, 0, 2).reshape(M, nb * C)
            drive = (self.ctrl @ X).reshape(2, nb, C).transpose(1, 0, 2).reshape(2 * nb, C)
            from_z, W = self._chain(nb)
            starts = from_z @ z + W @ drive                  # (2nb, C)
            z = self.A_pow[M] @ starts[-2:] + drive[-2:]
            S = starts.reshape(nb, 2, C).transpose(1, 0, 2).reshape(2, nb * C)
            Y = self.toeplitz @ X + self.obs @ S             # (M, nb C)
            y[done:end] = Y.reshape(M, nb, C).transpose(1, 0, 2).reshape(nb * M, C)
            done = end
        tail = T - done
        if tail:
            xt = x[done:]
            y[done:] = self.toeplitz[:tail, :tail] @ xt + self.obs[:tail] @ z
            z = self.A_pow[tail] @ z + self.ctrl[:, M - tail:] @ xt
        return y, z


class SosBlocks:
    """A cascade of second-order sections (rows b0 b1 b2 a0 a1 a2) run block by block."""

    def __init__(self, sos: np.ndarray, block: int = BLOCK):
        self.M = int(block)
        self.sections = [_Section(np.asarray(row, dtype=np.float64), self.M) for row in sos]

    def __call__(self, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """scipy.signal.sosfilt(sos, x, axis=0, zi=zi) for x (T, C), zi (S, 2, C): (y, zf)."""
        y = np.asarray(x, dtype=np.float64)
        zf = np.empty_like(zi)
        for s, sec in enumerate(self.sections):
            y, zf[s] = sec.run(y, zi[s])
        return y, zf
