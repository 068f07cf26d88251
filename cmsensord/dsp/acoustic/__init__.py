"""Vibration from microphone sound under background noise: a recursive Bayesian estimator.

Orimoto, Ikuta & Wang, "Bayesian estimation of machine vibration from sound observed under
background noise" (docs/references.md), eqs. (1)-(38), and the extended Kalman filter of
the same model the paper compares with.  Per block k (the board's block, 10 ms by
default): x_k the vibration energy (the accelerometer's block mean square; the daemon feeds
sqrt(x^_k), in m/s^2, to the AKF bank of Kim et al. 2023), y_k the machine's sound energy,
v_k the background noise's, z_k = y_k + v_k the microphone's block mean square, a_k the
sound-vibration correlation parameter.  The derivations, what the converted text of the
paper garbles, the safeguards and the results are in docs/acoustic.md ("docs §n" in the
modules is its section n).

Modules:

* :mod:`.model` — :class:`AcousticModel`, what the paper assumes known (fitted by
  :mod:`cmsensord.acoustic_calib`, stored by :mod:`cmsensord.acoustic_model`);
* :mod:`.step` — one step's :class:`Prior` and :class:`Posterior`, and the :class:`Guards`;
* :mod:`.polynomials` — the orthonormal families of the priors (eqs. 9, 10, 15);
* :mod:`.expansion` — the expansion coefficients A_lmn (eqs. 24-31);
* :mod:`.sound` — the machine sound y^, P_y (eqs. 21-22);
* :mod:`.update` — one update from the closed forms and the prediction (eqs. 16-19, 32-38);
* :mod:`.reference` — the same update by quadrature of the definitions, the plain
  reference the closed forms are tested against;
* :mod:`.blocks`, :mod:`.estimator`, :mod:`.ekf` — the estimator and the EKF over
  streams of blocks (T, C), state carried between calls.

Only numpy and the math module are used on the daemon's path; scipy.special is loaded by
the reference, :func:`laguerre_phi`, :func:`hermite_phi` and the tests.
"""

from __future__ import annotations

from cmsensord.dsp.acoustic.blocks import AcousticBlock, block_energy
from cmsensord.dsp.acoustic.ekf import AcousticEKF
from cmsensord.dsp.acoustic.estimator import AcousticEstimator
from cmsensord.dsp.acoustic.expansion import expansion_coefficients
from cmsensord.dsp.acoustic.model import AcousticModel
from cmsensord.dsp.acoustic.polynomials import hermite_phi, laguerre_phi, phi_z
from cmsensord.dsp.acoustic.reference import update_reference
from cmsensord.dsp.acoustic.sound import sound_coefficients, sound_estimate, sound_posterior
from cmsensord.dsp.acoustic.step import Guards, Posterior, Prior
from cmsensord.dsp.acoustic.update import A_MAX, predict, update_closed_form

__all__ = [
    "AcousticModel",
    "AcousticBlock",
    "AcousticEstimator",
    "AcousticEKF",
    "Prior",
    "Posterior",
    "block_energy",
    "laguerre_phi",
    "hermite_phi",
    "phi_z",
    "expansion_coefficients",
    "update_closed_form",
    "update_reference",
    "predict",
    "Guards",
    "A_MAX",
    "sound_estimate",
    "sound_coefficients",
    "sound_posterior",
]
