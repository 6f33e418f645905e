"""Every score of keyfill's protocols: L2Q, L2P and NPSS of the LaFAN1 benchmark, foot skating and jitter.

The in-betweening metrics of the LaFAN1 benchmark (Harvey et al. 2020). All three compare a prediction with the ground truth over the transition frames
only, on *global* (world) quantities, exactly as the benchmark's reference code
computes them:

* :func:`l2q`: mean over windows and frames of the Euclidean norm of the
  difference of the global quaternions (all joints x 4 components). Signs are
  not canonicalised, so ``q`` and ``-q`` count as different: predictions must
  keep the ground truth's quaternion hemisphere (continuous signs).
* :func:`l2p`: mean over windows and frames of the Euclidean norm of the
  difference of the normalised global positions ``(p - x_mean) / x_std``
  (``x_mean``, ``x_std``: per coordinate, from the training windows).
* :func:`npss`: Normalised Power Spectrum Similarity (Gopalakrishnan et al.
  2019) on global quaternions flattened to ``(windows, frames, joints * 4)``:
  the earth mover's distance between the normalised cumulative power spectra
  along time, averaged over (window, dimension) pairs weighted by the ground
  truth's power.

Realism measures that need no user study, foot skating and jitter. Both take global joint positions ``(N, T, J, 3)`` in the motion's units
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


def l2q(gt_quats: np.ndarray, pred_quats: np.ndarray) -> float:
    """L2Q of global quaternions ``(N, T, J, 4)`` (ground truth, prediction)."""
    gt, pred = _same_shape(gt_quats, pred_quats, 4)
    return float(np.mean(np.sqrt(np.sum((pred - gt) ** 2, axis=(2, 3)))))


def l2p(gt_positions: np.ndarray, pred_positions: np.ndarray, x_mean: np.ndarray, x_std: np.ndarray) -> float:
    """L2P of global positions ``(N, T, J, 3)``, normalised by ``x_mean``, ``x_std`` (``J * 3`` values each)."""
    gt, pred = _same_shape(gt_positions, pred_positions, 3)
    n, t = gt.shape[:2]
    mean = np.asarray(x_mean, dtype=np.float64).reshape(-1)
    std = np.asarray(x_std, dtype=np.float64).reshape(-1)
    g = (gt.reshape(n, t, -1) - mean) / std
    p = (pred.reshape(n, t, -1) - mean) / std
    return float(np.mean(np.sqrt(np.sum((p - g) ** 2, axis=2))))


def npss(gt: np.ndarray, pred: np.ndarray) -> float:
    """NPSS of sequences ``(N, T, D)`` (or ``(N, T, J, 4)``, flattened to ``D = J * 4``)."""
    gt = np.asarray(gt, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    if gt.shape != pred.shape:
        raise ValueError(f"ground truth {gt.shape} and prediction {pred.shape} differ in shape")
    gt = gt.reshape(gt.shape[0], gt.shape[1], -1)
    pred = pred.reshape(gt.shape)
    gt_power = np.real(np.fft.fft(gt, axis=1)) ** 2  # (N, T, D)
    pred_power = np.real(np.fft.fft(pred, axis=1)) ** 2
    gt_total = gt_power.sum(axis=1)  # (N, D)
    pred_total = pred_power.sum(axis=1)
    gt_cdf = np.cumsum(gt_power / gt_total[:, None], axis=1)
    pred_cdf = np.cumsum(pred_power / pred_total[:, None], axis=1)
    emd = np.abs(pred_cdf - gt_cdf).sum(axis=1)  # (N, D)
    return float(np.average(emd, weights=gt_total))


def _same_shape(gt, pred, last: int) -> tuple[np.ndarray, np.ndarray]:
    gt = np.asarray(gt, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    if gt.shape != pred.shape or gt.ndim != 4 or gt.shape[-1] != last:
        raise ValueError(f"expected two (windows, frames, joints, {last}) arrays, got {gt.shape} and {pred.shape}")
    return gt, pred

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
