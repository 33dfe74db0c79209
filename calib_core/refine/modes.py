"""The covariance of an answer whose runners-up the data leave nearly tied: the likelihood-weighted mixture of the
modes about the answer.

With few boards the likelihood can have several distinct optima (``robust.choose``: the runners-up within
``WEAK_LOG_LIKELIHOOD`` of the answer's cost, a negative log-likelihood). The covariance at the answer describes its
own mode only, so where the truth lies at a runner-up the reported 1-sigma misses it by many sigmas. The posterior,
approximated by one Gaussian per mode with the mode's likelihood as its weight, has about the answer the second
moment

    P = sum_i w_i (P_i + d_i d_i^T),   w_i = exp(-(cost_i - cost_0)) / sum_j exp(-(cost_j - cost_0)),

``i = 0`` the answer (``d_0 = 0``, ``P_0`` its covariance), ``d_i`` the runner-up's offset from the answer in the
covariance's parameters (``geometry.metrics.pose_error_vector``: rotation vector of ``R_i R_0^T`` in the lidar frame,
radians; ``t_i - t_0``, metres), ``cost_i`` its negative log-likelihood (``score.evidence_cost``: half a chi-square,
so ``exp(-cost)`` is the likelihood). ``P_i`` is the answer's covariance for every mode (a runner-up's own is not
computed: it would need the joint model at each): ``P = P_0 + sum_{i>0} w_i d_i d_i^T``, never smaller than
``P_0`` and equal to it without runners-up. The answer does not change.

``methods.lidarcam.finish`` applies it last: the profile floor, the per-board error's sandwich, the likelihood's bend,
the dispersion widening and a mounting prior's information all describe the answer's own mode (``P_0``); the mixture
composes the modes (with a prior, the runners-up were scored on the posterior).
"""

from __future__ import annotations

import numpy as np

from ..geometry.metrics import pose_error_vector, sigma_rot_deg, sigma_trans_m


def mode_weights(costs: np.ndarray) -> np.ndarray:
    """Each mode's likelihood weight ``exp(-(cost_i - min cost))``, normalised to sum 1; ``costs`` (M,) negative
    log-likelihoods, the answer's first."""
    c = np.asarray(costs, float)
    w = np.exp(-(c - c.min()))
    return w / w.sum()


def mixture_covariance(T: np.ndarray, cov: np.ndarray, cost: float, runners_up) -> tuple[np.ndarray, dict]:
    """The covariance (6x6, rotation then translation, ``data.residuals``' parameters about ``T``) of the modes the
    data leave nearly tied (module docstring) and what a result reports of it (``covariance_modes``: the modes'
    count, weights, offsets from the answer in degrees and millimetres and cost gaps, the 1-sigma in degrees and
    millimetres before and after); ``cov`` and an empty dict where ``runners_up`` (each (T_i, cost_i)) is empty.
    ``cost``: the answer's negative log-likelihood."""
    cov = np.asarray(cov, float)
    if not runners_up:
        return cov, {}
    Ts = [np.asarray(Ti, float) for Ti, _ in runners_up]
    costs = np.array([cost, *(c for _, c in runners_up)], float)
    w = mode_weights(costs)
    D = np.array([pose_error_vector(Ti, T) for Ti in Ts])                          # (M-1, 6)
    out = cov + np.einsum("i,ia,ib->ab", w[1:], D, D)
    out = 0.5 * (out + out.T)
    return out, {"n_modes": len(costs), "weights": [float(x) for x in w],
                 "cost_gaps": [float(x) for x in costs - costs[0]],
                 "offsets_deg": [0.0, *(float(np.degrees(np.linalg.norm(d[:3]))) for d in D)],
                 "offsets_mm": [0.0, *(float(1e3 * np.linalg.norm(d[3:])) for d in D)],
                 "sigma_rot_deg_mode": sigma_rot_deg(cov), "sigma_trans_mm_mode": 1e3 * sigma_trans_m(cov),
                 "sigma_rot_deg": sigma_rot_deg(out), "sigma_trans_mm": 1e3 * sigma_trans_m(out)}
