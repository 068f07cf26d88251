"""The extended Kalman filter of the acoustic model: the baseline Orimoto, Ikuta & Wang compare with.

docs/acoustic.md §8.
"""

from __future__ import annotations

import numpy as np

from cmsensord.dsp.acoustic.blocks import AcousticBlock, empty_block, fill_channel, stream_input
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.sound import sound_estimate

__all__ = ["AcousticEKF"]


class AcousticEKF:
    """The extended Kalman filter of the same model (the paper's baseline, ref. [11]).

    State s = (x, a); transition x_{k+1} = F x_k + G u_k, a_{k+1} = a_k (eqs.
    32-36); observation z = <z|x, a> + noise = alpha0 + a alpha1 theta1(x) + w
    with var(w) = var(z|x, a) = <z^2|x, a> - <z|x, a>^2 at the prior mean
    (floored at var(v)).  Linearised at the prior mean:
    H = (a* alpha1 lambda11, alpha1 theta1(x*)).  ``sound="posterior"``: y^, P_y the EKF's
    <y|Z_k> with y = <y|x, a> + w_y in the state (docs §8); ``sound="eq21"``: the printed
    eqs. (21)-(22) from the EKF's x^, a^.  No safeguards (a plain EKF).
    """

    def __init__(self, models, sound: str = "posterior"):
        if isinstance(models, AcousticModel):
            models = [models]
        if sound not in ("posterior", "eq21"):
            raise ValueError(f"sound must be 'posterior' or 'eq21', got {sound!r}")
        self.models = list(models)
        self.C = len(self.models)
        self.sound = sound
        self.reset()

    def reset(self) -> None:
        self.s = np.array([[m.x0, m.a0] for m in self.models])                   # (C, 2)
        self.P = np.array([[[m.gx0, 0.0], [0.0, m.ga0]] for m in self.models])   # (C, 2, 2)

    def process(self, z, valid=None) -> AcousticBlock:
        z, ok = stream_input(z, self.C, valid)
        T = z.shape[0]
        out = empty_block(T, self.C, ok)
        for c, m in enumerate(self.models):
            (l10, l11, _), (l20, l21, l22) = m.lam1[1], m.lam1[2]
            x, a = float(self.s[c, 0]), float(self.s[c, 1])
            pxx, pxa, paa = float(self.P[c, 0, 0]), float(self.P[c, 0, 1]), float(self.P[c, 1, 1])
            zc, okc = z[:, c].tolist(), ok[:, c].tolist()
            rows = []
            for k in range(T):
                t1 = l10 + l11 * x
                t2 = l20 + l21 * x + l22 * x * x
                h = m.alpha0 + a * m.e11 * t1
                var_z = m.beta0 + a * m.beta1 * t1 + a * a * m.p22 * t2 - h * h
                R = max(var_z, m.var_v, 1e-12 * h * h)
                Hx, Ha = a * m.e11 * l11, m.e11 * t1
                PHx = pxx * Hx + pxa * Ha
                PHa = pxa * Hx + paa * Ha
                HPH = Hx * PHx + Ha * PHa
                # y = <y|x, a> + w_y (var w_y = R - var v), z = y + v: y in the state (docs §8)
                cyz = HPH + R - m.var_v                     # prior var y = cov(y, z)
                y_hat, py = h - m.v1, cyz
                if okc[k]:
                    S = HPH + R
                    Kx, Ka = PHx / S, PHa / S
                    innov = zc[k] - h
                    x, a = x + Kx * innov, a + Ka * innov
                    y_hat, py = y_hat + cyz / S * innov, cyz - cyz * cyz / S
                    # Joseph form (I - K H) P (I - K H)' + K R K'
                    i00, i01 = 1.0 - Kx * Hx, -Kx * Ha
                    i10, i11 = -Ka * Hx, 1.0 - Ka * Ha
                    n00 = i00 * pxx + i01 * pxa
                    n01 = i00 * pxa + i01 * paa
                    n10 = i10 * pxx + i11 * pxa
                    n11 = i10 * pxa + i11 * paa
                    pxx = n00 * i00 + n01 * i01 + Kx * Kx * R
                    pxa = n00 * i10 + n01 * i11 + Kx * Ka * R
                    paa = n10 * i10 + n11 * i11 + Ka * Ka * R
                if self.sound == "eq21":
                    y_hat, py = sound_estimate(m, x, pxx, a, paa)
                rows.append((x, pxx, a, paa, y_hat, py, h))
                # prediction (32)-(38)
                x = m.F * x + m.G * m.u_mean
                pxx = m.F * m.F * pxx + m.G * m.G
                pxa = m.F * pxa
            fill_channel(out, c, rows)
            self.s[c] = (x, a)
            self.P[c] = ((pxx, pxa), (pxa, paa))
        return out
