"""The in-betweening metrics of the LaFAN1 benchmark (Harvey et al. 2020): L2Q, L2P, NPSS.

All three compare a prediction with the ground truth over the transition frames
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
"""

from __future__ import annotations

import numpy as np


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
