"""Closed loops: the regressor in the independent coordinates and its exact derivatives.

On a closed loop the tree coordinates follow the independent ones z through the closure
equations: q_d solves phi(q) = 0 (Newton, :mod:`baseparams.dynamics.evaluator`), qd = R zd
with R = [I; -J_d^-1 J_z], qdd = R zdd + s with s_d = -J_d^-1 gamma(q, qd), and the
regressor is K = R^T K_tree(q, qd, qdd). Differentiating these identities (never the Newton
iterations) gives, for each independent direction,

    dq/dz_k = R e_k,   J_d dR_d/dz_k = -(dJ/dz_k) R,   d(qd) = dR zd (+ R e_k for zd_k),
    J_d ds_d = -(dgamma + dJ_d s_d),   d(qdd) = dR zdd + ds (+ R e_k for zdd_k),
    dK = dR^T K_tree + R^T (dK_tree/dq dq + dK_tree/dqd dqd + dK_tree/dqdd dqdd),

with dJ/dq, dgamma/dq, dgamma/dqd and dK_tree from the forward-mode tangents of the generated
code (:mod:`.tangent`). Also the singularity margin (1/cond of J_d) and its derivative, from
the singular vectors of J_d.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from baseparams.dynamics.evaluator import Sample, closure_structure
from baseparams.excite.tangent import (closure_bias_with_tangents, closure_jacobian_with_tangents,
                                       tree_regressor_with_tangents)
from baseparams.model.mechanism import Mechanism


def _columns(values: Sequence[Any], count: int) -> np.ndarray:
    return np.stack([np.broadcast_to(np.asarray(v, dtype=float), (count,)) for v in values], axis=1)


def regressor_with_tangents(mechanism: Mechanism, sample: Sample, zd: np.ndarray,
                            zdd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(K (N, f, p), dK (3 f, N, f, p), margin (N,), dmargin (3 f, N)) at an evaluated closed
    loop ``sample`` (:class:`~baseparams.dynamics.evaluator.Sample`) with independent velocities
    and accelerations ``zd``, ``zdd`` (N, f); directions: z, zd, zdd of each independent coordinate."""
    st = closure_structure(mechanism)
    ind, dep, rows = list(st.independent), list(st.dependent), list(st.rows)
    count = zd.shape[0]
    n, f = len(mechanism.coordinates), len(ind)
    q, qd, qdd = (_columns(v, count) for v in (sample.q, sample.qd, sample.qdd))
    R = np.stack([_columns(row, count) for row in sample.projection], axis=1)          # (N, n, f)
    J, dJ = closure_jacobian_with_tangents(mechanism, q)
    Jr, dJr = J[:, rows], dJ[:, :, rows]
    Jd = Jr[:, :, dep]
    Jd_inv = np.linalg.inv(Jd)
    dJz = np.einsum("inab,nik->knab", dJr, R)                                          # (f, N, r, n)
    dR = np.zeros((f, count, n, f))
    dR[:, :, dep, :] = -np.einsum("nab,knbc,ncf->knaf", Jd_inv, dJz, R)
    gamma, dgamma = closure_bias_with_tangents(mechanism, q, qd)
    g_q, g_qd = dgamma[:n][:, :, rows], dgamma[n:][:, :, rows]
    s_d = -np.einsum("nab,nb->na", Jd_inv, gamma[:, rows])
    # derivatives of the tree inputs (q, qd, qdd) along each independent direction
    T = np.zeros((3 * f, count, 3, n))
    dqd_z = np.einsum("knif,nf->kni", dR, zd)
    dg_z = np.einsum("inm,nik->knm", g_q, R) + np.einsum("inm,kni->knm", g_qd, dqd_z)
    ds_z = -np.einsum("nab,knb->kna", Jd_inv, dg_z + np.einsum("knab,nb->kna", dJz[..., dep], s_d))
    T[:f, :, 0] = R.transpose(2, 0, 1)
    T[:f, :, 1] = dqd_z
    T[:f, :, 2] = np.einsum("knif,nf->kni", dR, zdd)
    T[:f, :, 2][:, :, dep] += ds_z
    ds_zd = -np.einsum("nab,knb->kna", Jd_inv, np.einsum("inm,nik->knm", g_qd, R))
    T[f:2 * f, :, 1] = R.transpose(2, 0, 1)
    T[f:2 * f, :, 2][:, :, dep] = ds_zd
    T[2 * f:, :, 2] = R.transpose(2, 0, 1)
    K_tree, dK_tree = tree_regressor_with_tangents(mechanism, q, qd, qdd)
    dK_tree = dK_tree.reshape((3, n) + dK_tree.shape[1:])
    dKt = np.einsum("dngi,ginap->dnap", T, dK_tree)
    K = np.einsum("nif,nip->nfp", R, K_tree)
    dK = np.einsum("nif,dnip->dnfp", R, dKt)
    dK[:f] += np.einsum("knif,nip->knfp", dR, K_tree)
    U, S, Vt = np.linalg.svd(Jd)
    margin = S[:, -1] / S[:, 0]
    dJd = dJz[..., dep]
    d_small = np.einsum("na,knab,nb->kn", U[:, :, -1], dJd, Vt[:, -1, :])
    d_large = np.einsum("na,knab,nb->kn", U[:, :, 0], dJd, Vt[:, 0, :])
    dmargin = np.zeros((3 * f, count))
    dmargin[:f] = d_small / S[:, 0] - margin * d_large / S[:, 0]
    return K, dK, margin, dmargin
