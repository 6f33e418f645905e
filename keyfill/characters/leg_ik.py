"""The legs' two-bone IK of :func:`keyfill.characters.feet.lock_feet`: thighs, shins and feet turned so the
ankles reach their targets, in local rotations.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.kinematics import two_bone_ik


def solve_legs(rotations, W, P, col, rows, legs, chains, sides, parents, shift, targets, changed) -> np.ndarray:
    """Two-bone IK of both legs on the frames ``rows (n,)``, written into ``rotations (F, J, 4)`` (local, in
    place) where ``changed (n, 2)``; returns the solved ankles' world positions ``(n, 2, 3)``. ``W (n, S, 4)``,
    ``P (n, S, 3)``: the legs' world rotations and positions on those frames (``feet._chain_world``), joint
    ``j`` in column ``col[j]``; ``shift (n, 3)``: the hips' drop; ``targets (n, 2, 3)``: the ankles'.

    The thigh gets ``qa W``, the shin ``qb qa W``, the foot its old world rotation; the knee bends towards
    its side in the motion (plus a hundredth of the leg towards the toes, for a straight knee)."""
    sh = shift[:, None, :]
    Pf = P
    a, b, c = (Pf[:, col[legs[:, i]]] + sh for i in range(3))  # (n, 2, 3)
    ac = (c - a) / np.linalg.norm(c - a, axis=-1, keepdims=True)
    pole = (b - a) - ac * np.sum((b - a) * ac, axis=-1, keepdims=True)
    toes = [chains[s][3] for s in sides]
    if all(t is not None for t in toes):
        fwd = Pf[:, col[toes]] - Pf[:, col[legs[:, 2]]]
        fwd /= np.maximum(np.linalg.norm(fwd, axis=-1, keepdims=True), 1e-300)
        pole = pole + 0.01 * np.linalg.norm(b - a, axis=-1, keepdims=True) * fwd
    qa, qb = two_bone_ik(a, b, c, targets, pole)
    qba = R.quat_mul(qb, qa)
    solved = a + R.quat_rotate(qa, b - a) + R.quat_rotate(qba, c - b)
    for i in range(len(sides)):
        sel = changed[:, i]
        (thigh, shin, foot), rows_i = legs[i], rows[sel]
        qa_i, qba_i, Wi = qa[sel, i], qba[sel, i], W[sel]
        parent_thigh = Wi[:, col[parents[thigh]]] if parents[thigh] >= 0 else R.quat_identity((len(rows_i),))
        w = {j: Wi[:, col[j]] for j in (thigh, shin, foot, parents[shin], parents[foot])}
        new = {
            thigh: R.quat_mul(R.quat_conjugate(parent_thigh), R.quat_mul(qa_i, w[thigh])),
            shin: R.quat_mul(R.quat_conjugate(R.quat_mul(qa_i, w[parents[shin]])), R.quat_mul(qba_i, w[shin])),
            foot: R.quat_mul(R.quat_conjugate(R.quat_mul(qba_i, w[parents[foot]])), w[foot]),
        }
        for j, q in new.items():  # in the old rotation's hemisphere
            q = R.quat_normalize(q)
            rotations[rows_i, j] = np.where(np.sum(q * rotations[rows_i, j], axis=-1, keepdims=True) < 0, -q, q)
    return solved
