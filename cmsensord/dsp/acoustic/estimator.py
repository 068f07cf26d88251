"""The acoustic estimator of Orimoto, Ikuta & Wang over streams of blocks (docs/acoustic.md §4-§5).

Per block and channel: the update from the closed forms (eqs. 16-31), then the prediction
(eqs. 32-38); a missing observation (lost frame, NaN) is a prediction without an update.
The per-step arithmetic is plain Python floats: for one or two microphone channels that
is faster than numpy per step.
"""

from __future__ import annotations

import numpy as np

from cmsensord.dsp.acoustic.blocks import AcousticBlock, empty_block, fill_channel, stream_input
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.step import DEFAULT_GUARDS, Guards, Prior
from cmsensord.dsp.acoustic.update import predict, update_closed_form

__all__ = ["AcousticEstimator"]


class AcousticEstimator:
    """The estimator of Orimoto, Ikuta & Wang for C microphone channels, one model each.

    ``process(z, valid)`` runs T blocks of sound energy (T, C); the priors
    (x*, Gamma_x, a*, Gamma_a per channel) are carried between calls, so any
    split of the stream gives the same estimates as one pass.
    """

    def __init__(self, models, guards: Guards | None = DEFAULT_GUARDS):
        if isinstance(models, AcousticModel):
            models = [models]
        self.models = list(models)
        if not self.models:
            raise ValueError("need at least one AcousticModel")
        self.C = len(self.models)
        self.guards = guards
        self.reset()

    def reset(self) -> None:
        m = self.models
        self.x = np.array([mm.x0 for mm in m])      # x*_k
        self.gx = np.array([mm.gx0 for mm in m])    # Gamma_x,k
        self.a = np.array([mm.a0 for mm in m])      # a*_k
        self.ga = np.array([mm.ga0 for mm in m])    # Gamma_a,k

    def state(self) -> dict:
        return {k: getattr(self, k).copy() for k in ("x", "gx", "a", "ga")}

    def process(self, z, valid=None) -> AcousticBlock:
        z, ok = stream_input(z, self.C, valid)
        T = z.shape[0]
        out = empty_block(T, self.C, ok)
        g = self.guards
        for c, model in enumerate(self.models):
            prior = Prior(float(self.x[c]), float(self.gx[c]), float(self.a[c]), float(self.ga[c]))
            zc, okc = z[:, c].tolist(), ok[:, c].tolist()
            rows = []
            for k in range(T):
                post = update_closed_form(model, prior, zc[k] if okc[k] else None, g)
                rows.append((post.x, post.px, post.a, post.pa, post.y, post.py, post.z_pred))
                prior = predict(model, post, g)
            fill_channel(out, c, rows)
            self.x[c], self.gx[c], self.a[c], self.ga[c] = prior.x, prior.gx, prior.a, prior.ga
        return out
