"""Realism measures that need no user study: foot skating and jitter of global joint positions.

Both take global joint positions ``(N, T, J, 3)`` in the motion's units
(``meters_per_unit`` converts them) at ``fps`` frames per second, and report
in fixed units whatever the corpus:

* :func:`foot_skating` (cm/s): the mean horizontal speed of the foot joints
  while they touch the ground. A foot joint touches the ground on a frame pair
  ``(t, t+1)`` when on both frames its height is within :data:`CONTACT_HEIGHT_M`
  (2.5 cm) of its lowest height in the reference sequence (the ground truth of
  the same window: the floor does not move with the method). Speeds are
  averaged over all such (window, joint, frame pair); real motion is not zero
  (a planted foot rolls from heel to toe), so compare with the ground truth's
  figure, which :func:`foot_skating` gives with ``reference=positions``.
* :func:`jitter` (m/s^3): the mean norm of the third finite difference of every
  joint's position, ``|p[t+1] - 3 p[t] + 3 p[t-1] - p[t-2]| * fps^3``: the
  jerk, which is large where a motion shakes or snaps.

Foot joints are found by name (:func:`foot_joints`): joints whose name holds
``foot``, ``toe``, ``ankle`` or ``heel`` (any case), else the two lowest joints
without children in the rest pose.
"""

from __future__ import annotations

import numpy as np

from keyfill.motion import Skeleton

#: a foot joint within this height of its lowest height touches the ground (meters)
CONTACT_HEIGHT_M = 0.025
FOOT_WORDS = ("foot", "toe", "ankle", "heel")
_AXES = {"X": 0, "Y": 1, "Z": 2}


def foot_joints(skeleton: Skeleton) -> np.ndarray:
    """Indices of the foot joints of ``skeleton`` (by name, else the two lowest leaf joints at rest)."""
    named = [j for j, n in enumerate(skeleton.names) if any(w in n.lower() for w in FOOT_WORDS)]
    if named:
        return np.array(named, dtype=np.int64)
    from keyfill.kinematics import fk

    J = len(skeleton.names)
    rest = fk(np.tile([1.0, 0.0, 0.0, 0.0], (J, 1)), skeleton.offsets, skeleton.parents)[1]
    leaves = np.setdiff1d(np.arange(J), skeleton.parents[skeleton.parents >= 0])
    up = _AXES[skeleton.up_axis]
    return np.sort(leaves[np.argsort(rest[leaves, up], kind="stable")[:2]])


def foot_skating(positions: np.ndarray, feet: np.ndarray, up_axis: str, fps: float, meters_per_unit: float,
                 reference: np.ndarray | None = None) -> float:
    """Mean horizontal speed of the feet in ground contact, in cm/s (see the module docstring).

    Args:
        positions: ``(N, T, J, 3)`` global joint positions.
        feet: indices of the foot joints.
        up_axis: ``"Y"`` or ``"Z"``.
        fps: frames per second.
        meters_per_unit: size of a position unit in meters.
        reference: ``(N, T', J, 3)`` positions whose lowest foot heights are the ground (default: ``positions``).

    Returns NaN when no foot touches the ground.
    """
    p = np.asarray(positions, dtype=np.float64)[:, :, feet]  # (N, T, F, 3)
    ref = p if reference is None else np.asarray(reference, dtype=np.float64)[:, :, feet]
    up = _AXES[up_axis]
    ground = ref[..., up].min(axis=1, keepdims=True)  # (N, 1, F)
    low = (p[..., up] - ground) <= CONTACT_HEIGHT_M / meters_per_unit  # (N, T, F)
    contact = low[:, 1:] & low[:, :-1]
    if not contact.any():
        return float("nan")
    flat = [a for a in range(3) if a != up]
    step = np.linalg.norm(np.diff(p[..., flat], axis=1), axis=-1)  # (N, T-1, F)
    return float(step[contact].mean() * fps * meters_per_unit * 100.0)


def jitter(positions: np.ndarray, fps: float, meters_per_unit: float) -> float:
    """Mean norm of the third difference of joint positions ``(N, T, J, 3)`` (T >= 4), in m/s^3."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[1] < 4:
        raise ValueError(f"jitter needs at least 4 frames, got {p.shape[1]}")
    third = p[:, 3:] - 3 * p[:, 2:-1] + 3 * p[:, 1:-2] - p[:, :-3]
    return float(np.linalg.norm(third, axis=-1).mean() * fps**3 * meters_per_unit)
