"""Style augmentation of training windows: postures and tempos the training styles lack (issue 30).

A model trained on a few motion styles meets other styles in use: an elderly walk is hunched and slow, a
proud one upright, a tired one drooping. Two cheap changes to a training window imitate the differences
that do not need new physics:

* **Posture** (:func:`perturb_posture`): every torso joint above the hips (the humanoid roles' spine and neck
  chains, the head and the clavicles; :func:`posture_joints`) gets one constant random rotation for the
  whole window, post-multiplied onto its local rotation (so it turns the joint's subtree in the joint's own
  frame). The legs and the root are untouched: the feet keep their contacts and the motion its dynamics,
  only the carriage of the upper body changes.
* **Tempo** (:func:`retime`): the window is played slower, at a speed ``s`` in ``[low, 1]``: frame ``i``
  shows the original motion at time ``start + i s`` (linear interpolation of the root, SLERP of the local
  rotations), ``start`` chosen so the slowed window stays inside the original one.

Both draw from a caller's ``numpy.random.Generator`` and leave the input arrays unchanged.
"""

from __future__ import annotations

import numpy as np

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.characters.humanoid import map_roles
from keyfill.errors import DataError
from keyfill.motion import Skeleton

#: share of the windows of a batch that :func:`retime` slows down (the others keep their tempo)
RETIME_SHARE = 0.5


def posture_joints(skeleton: Skeleton) -> np.ndarray:
    """``(n,)`` int indices of the torso joints whose carriage :func:`perturb_posture` changes: the spine and
    neck chains, the head and the clavicles of :func:`keyfill.characters.humanoid.map_roles`, in that order.
    A :class:`DataError` naming ``posture_angle`` for a skeleton that is no humanoid."""
    try:
        roles = map_roles(skeleton, label="the training clips' skeleton")
    except DataError as e:  # without its advice on rig maps: training takes none
        raise DataError(f"posture_angle needs a humanoid skeleton: {str(e).split('; name them')[0]}; "
                        "set posture_angle to 0 for this corpus") from None
    clavicles = [roles.limbs[c] for c in ("clavicle_l", "clavicle_r") if c in roles.limbs]
    joints = [*roles.spine, *roles.neck, roles.head, *clavicles]
    if not joints:
        raise DataError("posture augmentation: the skeleton has no spine, neck, head or clavicle joint")
    return np.asarray(joints, dtype=np.int64)


def perturb_posture(rng: np.random.Generator, quats: np.ndarray, joints: np.ndarray,
                    angle: float) -> np.ndarray:
    """``quats (B, T, J, 4)`` with a constant rotation per window and joint of ``joints`` post-multiplied.

    Each rotation turns about a uniformly random axis by an angle uniform in ``[0, angle]`` radians, the same
    on every frame of its window. Returns a new float64 array.
    """
    B, n = quats.shape[0], len(joints)
    axis = rng.normal(size=(B, n, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    offsets = R.quat_from_rotvec(axis * rng.uniform(0.0, angle, size=(B, n, 1)))  # (B, n, 4)
    out = np.array(quats, dtype=np.float64)
    out[:, :, joints] = R.quat_mul(out[:, :, joints], offsets[:, None])
    return out


def retime(rng: np.random.Generator, quats: np.ndarray, root: np.ndarray, low: float,
           contacts: np.ndarray | None = None):
    """Slow a random :data:`RETIME_SHARE` of the windows to a speed uniform in ``[low, 1]``.

    Args:
        quats: ``(B, T, J, 4)`` local rotations, signs continuous along time (as a corpus keeps them).
        root: ``(B, T, 3)`` root positions.
        low: the slowest speed, in ``(0, 1]``.
        contacts: optional ``(B, T, n)`` bool labels, resampled at the nearest original frame.

    Returns:
        ``(quats, root, contacts)``: new arrays (float64; contacts None when not given); the windows kept
        at their tempo are copies of the input.
    """
    B, T = root.shape[:2]
    slow = np.flatnonzero(rng.random(B) < RETIME_SHARE)
    speed = rng.uniform(low, 1.0, size=len(slow))
    start = rng.random(len(slow)) * (T - 1) * (1.0 - speed)
    t = start[:, None] + np.arange(T) * speed[:, None]  # (S, T) original time of each new frame
    q, r = np.array(quats, dtype=np.float64), np.array(root, dtype=np.float64)
    for i, window in enumerate(slow):
        q[window], r[window] = interpolate.at_times(q[window], r[window], t[i])
    c = None
    if contacts is not None:
        c = np.array(contacts)
        c[slow] = contacts[slow[:, None], np.minimum(np.rint(t).astype(np.int64), T - 1)]
    return q, r, c
