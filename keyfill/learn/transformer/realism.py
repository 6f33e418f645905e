"""The transformer's realism terms (issue 30): feet that stay planted and no jitter beyond the real clip's.

Both are measured on the positions the model's user gets, forward kinematics of the decoded output
(:meth:`~keyfill.learn.transformer.features.Features.decode`), over the frames that carry a loss (not the
IGNORED tail of an in-betweening window), and added to the training loss with the weights
:attr:`~keyfill.learn.transformer.config.ModelConfig.foot_weight` and
:attr:`~keyfill.learn.transformer.config.ModelConfig.smooth_weight` (both 0 by default: the shipped model
trained without them, and a run without them draws the same batches and writes the same bytes as before).

* foot sliding (:func:`keyfill.learn.realism_terms.foot_sliding_loss`, (m/s)^2) over the contact labels of
  the real window: labels of every training clip are computed once when the task starts
  (:func:`contact_windows`) and cut as the windows are; a mirrored window's columns swap left and right
  (:func:`column_swap`);
* excess jerk (:func:`keyfill.learn.realism_terms.excess_jerk_loss`, m/s^3) against the real window.

No torch at import.
"""

from __future__ import annotations

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.realism_terms import corpus_contacts, excess_jerk_loss, foot_sliding_loss
from keyfill.learn.transformer.features import IGNORED


def contact_windows(train, window: int, offset: int) -> tuple[np.ndarray, np.ndarray]:
    """``(labels (W, window, n) bool, joints (n,))``: the contact labels of the training windows of corpus
    ``train`` (``Corpus.windows(window, offset)``, in their order), computed per clip."""
    labels, joints = corpus_contacts(train)
    frames, _, _ = train.window_frames(window, offset)
    return labels[frames].reshape(len(frames), window, len(joints)), joints


def column_swap(mirror, joints: np.ndarray) -> np.ndarray:
    """``(n,)``: column ``i`` of a mirrored window's labels is column ``swap[i]`` of the original's (the
    mirror gives joint ``perm[j]`` the motion of joint ``j``: ``foot_l`` <-> ``foot_r``, ``toe_l`` <-> ``toe_r``)."""
    column = {int(j): i for i, j in enumerate(joints)}
    try:
        return np.array([column[int(mirror.perm[j])] for j in joints], dtype=np.int64)
    except KeyError:
        raise DataError("the mirror of a foot joint is no foot joint: the contacts of mirrored windows are "
                        "unknown (turn mirror or foot_weight off)") from None


def realism_losses(feat, pred, gt_quats, gt_root, kinds, cfg, *, contact=None, joints=None, fps: float,
                   up: int, meters_per_unit: float) -> dict:
    """``{"foot", "smooth"}`` (those whose weight in ``cfg`` is not 0; "foot" also needs contact labels): the
    unweighted terms of a batch (torch scalars).

    Args:
        feat: the model's features; pred: ``(B, T, F)`` network output; gt_quats, gt_root: the true window.
        kinds: ``(B, T)`` frame kinds; cfg: the :class:`~keyfill.learn.transformer.config.ModelConfig`.
        contact: ``(B, T, n)`` bool labels of the true window; joints: ``(n,)`` their joints.
        fps, up, meters_per_unit: the corpus's frame rate, up axis index and unit.
    """
    out = {}
    want_feet = bool(cfg.foot_weight) and contact is not None and joints is not None and len(joints) > 0
    if not (want_feet or cfg.smooth_weight):
        return out
    w = (kinds != IGNORED).to(pred.dtype)  # (B, T)
    dq, droot = feat.decode(pred)
    _, world = feat.global_pose(dq, droot)  # (B, T, J, 3), file units
    if want_feet:
        out["foot"] = foot_sliding_loss(world[:, :, joints] * meters_per_unit, contact, fps, up,
                                        pairs=w[:, 1:] * w[:, :-1])
    if cfg.smooth_weight:
        _, true = feat.global_pose(gt_quats, gt_root)
        quads = w[:, 3:] * w[:, 2:-1] * w[:, 1:-2] * w[:, :-3]
        out["smooth"] = excess_jerk_loss(world, true, fps**3 * meters_per_unit, quads=quads)
    return out
