"""Left-right mirroring of the clips of one skeleton, to double a training corpus (LaFAN1 practice).

:func:`find_mirror` finds each joint's mirror image and, per joint, the reflection that maps its mirrored
bones onto its own; the :class:`Mirror` it returns mirrors arrays of local quaternions and root positions.
Sides come from joint names where they pair every sided joint (:func:`mirror_pairs`: Bandai's ``_L``/``_R``,
Mixamo's ``Left``/``Right``), else from the humanoid roles of :func:`keyfill.characters.humanoid.map_roles`
(:func:`role_pairs`: ASF's ``lfemur``, Blender's ``thigh`` / ``thigh.001``, whose names do not pair), the left
and right joint of each limb role, extended along the hierarchy to the joints between them and the torso
and to the joints below them. Wrong pairs are never used: every pairing must keep the hierarchy and its bone
offsets must mirror onto each other, or there is no mirror (None).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from keyfill import rotations as R
from keyfill.motion import Skeleton

_SIDE_RULES = (
    (re.compile(r"([_.])([LlRr])$"), lambda m: m.group(1) + {"L": "R", "R": "L", "l": "r", "r": "l"}[m.group(2)]),
    (re.compile(r"^([LlRr])([_.])"), lambda m: {"L": "R", "R": "L", "l": "r", "r": "l"}[m.group(1)] + m.group(2)),
    (re.compile(r"Left|Right|left|right"), lambda m: {"Left": "Right", "Right": "Left", "left": "right", "right": "left"}[m.group(0)]),
)


def mirror_pairs(names: Sequence[str]) -> np.ndarray | None:
    """``(J,)`` index of each joint's mirror image by its name (itself for the centre line).

    Sides are recognised as a ``_L``/``_R`` (or ``.L``, ``_l``) suffix, an
    ``L_``/``R_`` prefix, or the words ``Left``/``Right``. None when no joint
    has a side, or a side has no partner.
    """
    index = {n: i for i, n in enumerate(names)}
    perm = np.arange(len(names))
    paired = False
    for i, n in enumerate(names):
        for pattern, swap in _SIDE_RULES:
            other = pattern.sub(swap, n, count=1)
            if other != n:
                if other not in index:
                    return None
                perm[i] = index[other]
                paired = True
                break
    return perm if paired else None


def _reflections() -> np.ndarray:
    """The 24 signed permutation matrices with determinant -1, ``(24, 3, 3)``."""
    out = []
    for p in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        for s in np.ndindex(2, 2, 2):
            m = np.zeros((3, 3))
            m[range(3), p] = 1 - 2 * np.asarray(s)
            if np.linalg.det(m) < 0:
                out.append(m)
    return np.array(out)


def _mean_rotation(q: np.ndarray) -> np.ndarray:
    """Chordal mean of unit quaternions ``(N, 4)`` (signs aligned to the first)."""
    q = np.where(np.sum(q * q[:1], axis=-1, keepdims=True) < 0, -q, q)
    return R.quat_normalize(q.mean(axis=0))


@dataclass(frozen=True, eq=False)
class Mirror:
    """Left-right mirroring of motions of one skeleton.

    The mirrored pose gives joint ``perm[m]`` the global rotation ``W G_m A_m``
    and the root the position ``W p``, where ``W`` reflects the world's first
    ground axis (X) and ``A_m`` is a constant reflection that maps the joint's
    mirrored bone directions onto its own. In quaternions: local rotations
    ``conj(a_parent) * q_m * a_m`` with ``a = quat(-A)``, the root
    ``quat(-W) * q_root * a_root``.

    Attributes:
        perm: ``(J,)`` mirror joint of every joint.
        a: ``(J, 4)`` the quaternions of ``-A_m``.
        parents: ``(J,)`` the skeleton's parents.
    """

    perm: np.ndarray
    a: np.ndarray
    parents: np.ndarray

    def __call__(self, quats: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mirror ``quats (..., J, 4)`` and ``root (..., 3)``."""
        par = self.parents
        left = np.array([self.a[p] if p >= 0 else [0.0, -1.0, 0.0, 0.0] for p in par])  # conj(quat(-W)) for the root
        src = R.quat_mul(R.quat_mul(R.quat_conjugate(left), quats), self.a)  # (..., J, 4), joint m's new rotation
        out = np.empty_like(src)
        out[..., self.perm, :] = src
        r = np.array(root, dtype=np.float64)
        r[..., 0] = -r[..., 0]
        return out, r


def role_pairs(skeleton: Skeleton) -> np.ndarray | None:
    """``(J,)`` index of each joint's mirror image by the humanoid roles (itself for the centre line).

    The left and right joints of each limb role (:data:`keyfill.characters.humanoid.LIMB_ROLES`) pair; then,
    until nothing changes, the parents of two paired joints pair when they differ and play no centre role (a
    CMU ``LHipJoint`` above the thigh, a twist joint inside an arm), and the children of two paired joints
    pair in their order when both have as many (fingers, toe ends). Joints left over are the centre line.
    None when the skeleton has no humanoid roles, or a limb role exists on one side only.
    """
    from keyfill.characters.humanoid import LIMB_ROLES, map_roles
    from keyfill.errors import KeyfillError

    try:
        roles = map_roles(skeleton)
    except KeyfillError:
        return None
    J, par = skeleton.num_joints, np.asarray(skeleton.parents)
    perm = np.arange(J)
    centre = {roles.hips, roles.head, *roles.spine, *roles.neck}
    for role in LIMB_ROLES:
        a, b = roles.limbs.get(f"{role}_l"), roles.limbs.get(f"{role}_r")
        if (a is None) != (b is None):
            return None
        if a is not None:
            perm[a], perm[b] = b, a
    children = [skeleton.children(j) for j in range(J)]

    def free(j):
        return perm[j] == j and j not in centre

    changed = True
    while changed:
        changed = False
        for m in range(J):
            n = int(perm[m])
            if n == m:
                continue
            pm, pn = int(par[m]), int(par[n])
            if pm >= 0 and pn >= 0 and pm != pn and free(pm) and free(pn):
                perm[pm], perm[pn] = pn, pm
                changed = True
            if len(children[m]) == len(children[n]):
                for a, b in zip(children[m], children[n]):
                    if a != b and free(a) and free(b):
                        perm[a], perm[b] = b, a
                        changed = True
    return perm if np.any(perm != np.arange(J)) else None


def _keeps_hierarchy(perm: np.ndarray, par: np.ndarray) -> bool:
    """Whether ``perm`` maps the root to the root and every joint's parent to its image's parent."""
    return not any((par[m] < 0) != (par[perm[m]] < 0) or (par[m] >= 0 and perm[par[m]] != par[perm[m]])
                   for m in range(len(par)))


def find_mirror(skeleton: Skeleton, quats: np.ndarray, tolerance: float = 0.05) -> Mirror | None:
    """The :class:`Mirror` of ``skeleton``, or None when the skeleton does not allow one.

    Needs left/right pairs that keep the hierarchy: by joint names
    (:func:`mirror_pairs`) where they pair, else by the humanoid roles
    (:func:`role_pairs`); and for every joint a reflection ``A`` among the signed axis
    permutations that maps its mirrored children's offsets onto its own
    (within ``tolerance`` of the bone length). Where several fit (a single
    straight child, a leaf), the one whose mirrored mean rotation in ``quats``
    (``(N, J, 4)``, a sample of the corpus) best matches the mirror joint's
    mean rotation is taken.
    """
    par = np.asarray(skeleton.parents)
    if skeleton.up_axis != "Y":
        return None
    perm = mirror_pairs(skeleton.names)
    if perm is None or not _keeps_hierarchy(perm, par):
        perm = role_pairs(skeleton)
        if perm is None or not _keeps_hierarchy(perm, par):
            return None
    off = skeleton.offsets
    cands = _reflections()
    mean = np.array([_mean_rotation(quats[:, j]) for j in range(len(par))])
    chosen: dict[int, np.ndarray] = {}

    def constraint_children(m):
        out = []
        for c in skeleton.children(m):
            if np.linalg.norm(off[c]) > 1e-9:
                out.append(c)
            elif np.allclose(np.abs(quats[:, c, 0]), 1.0, atol=1e-6):  # a zero-length static joint: look through it
                out.extend(constraint_children(c))
        return out

    for m in range(len(par)):
        ok = []
        for A in cands:
            err = [np.linalg.norm(A @ off[perm[c]] - off[c]) / max(np.linalg.norm(off[c]), 1e-9)
                   for c in constraint_children(m)]
            if all(e < tolerance for e in err):
                ok.append(A)
        if not ok:
            return None
        if len(ok) > 1:
            if par[m] < 0:
                return None  # the root's reflection must follow from its bones
            a_p = R.quat_from_matrix(-chosen[par[m]])
            dist = [R.quat_angle(R.quat_mul(R.quat_mul(R.quat_conjugate(a_p), mean[m]), R.quat_from_matrix(-A)),
                                 mean[perm[m]]) for A in ok]
            ok = [ok[int(np.argmin(dist))]]
        chosen[m] = ok[0]
    a = np.array([R.quat_from_matrix(-chosen[m]) for m in range(len(par))])
    return Mirror(perm, a, np.asarray(par))
