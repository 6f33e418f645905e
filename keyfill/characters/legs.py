"""The legs of :func:`keyfill.characters.feet.lock_feet`: their forward kinematics a block of frames at a time
(:func:`leg_chain`, :func:`chain_world`, :func:`leg_world`), and their two-bone IK (:func:`solve_legs`): thighs,
shins and feet turned so the ankles reach their targets, in local rotations.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.kinematics import fk, two_bone_ik
from keyfill.motion import Skeleton

#: frames whose leg kinematics and IK are computed at once (their temporaries: a few MB, for any length)
BLOCK = 4096


def ancestors(parents: np.ndarray, j: int) -> list[int]:
    """``j``'s ancestors, nearest first."""
    out = []
    while parents[j] >= 0:
        j = int(parents[j])
        out.append(j)
    return out


def leg_chain(skeleton: Skeleton, joints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(sub (S,), sub_parents (S,), column (J,))``: ``joints`` and their ``S`` ancestors, their parents among
    them, and the column of joint ``j`` in arrays of the ``S`` (-1 for the joints left out)."""
    parents = skeleton.parents
    sub = np.array(sorted({int(k) for j in joints for k in [j, *ancestors(parents, j)]}))
    column = np.full(skeleton.num_joints, -1)
    column[sub] = np.arange(len(sub))
    sub_parents = np.array([column[parents[j]] if parents[j] >= 0 else -1 for j in sub])
    return sub, sub_parents, column


def chain_world(rotations: np.ndarray, positions: np.ndarray, chain, rows) -> tuple[np.ndarray, np.ndarray]:
    """World ``(rotations (n, S, 4), positions (n, S, 3))`` of :func:`leg_chain`'s joints on the frames
    ``rows`` (a slice or indices) of local ``rotations (F, J, 4)``, ``positions (F, J, 3)``."""
    sub, sub_parents, _ = chain
    return fk(rotations[rows][:, sub], positions[rows][:, sub], sub_parents)


def leg_world(rotations: np.ndarray, positions: np.ndarray, skeleton: Skeleton, joints) -> tuple[np.ndarray, ...]:
    """World ``(rotations (F, S, 4), positions (F, S, 3), column (J,) int)`` of ``joints`` and their ``S``
    ancestors by forward kinematics of those joints alone (the legs of a 55-joint rig are 10): joint ``j``'s
    are column ``column[j]`` (-1 for the joints left out)."""
    chain = leg_chain(skeleton, joints)
    F, S = len(rotations), len(chain[0])
    W, P = np.empty((F, S, 4)), np.empty((F, S, 3))
    for a in range(0, F, BLOCK):  # a block of frames at a time: the temporaries stay small
        W[a : a + BLOCK], P[a : a + BLOCK] = chain_world(rotations, positions, chain, slice(a, a + BLOCK))
    return W, P, chain[2]


def solve_legs(rotations, W, P, col, rows, legs, chains, sides, parents, shift, targets, changed) -> np.ndarray:
    """Two-bone IK of both legs on the frames ``rows (n,)``, written into ``rotations (F, J, 4)`` (local, in
    place) where ``changed (n, 2)``; returns the solved ankles' world positions ``(n, 2, 3)``. ``W (n, S, 4)``,
    ``P (n, S, 3)``: the legs' world rotations and positions on those frames (:func:`chain_world`), joint
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
