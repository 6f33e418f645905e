"""Training terms for realism that any learned method may add to its loss: feet that stay planted where the
real clip's do, and no more jitter than the real clip has (issue 30; the transformer uses them, the gan's own
foot term, ``keyfill.learn.gan.losses.foot_sliding_loss``, is the same formula and could adopt this one).

* :func:`corpus_contacts`: the foot contact labels of every frame of a corpus, from
  :func:`keyfill.characters.feet.contacts` (the labels ``keyfill complete --feet`` and the benchmarks use),
  computed per clip, so that windows cut from the corpus cut their labels with
  :meth:`keyfill.learn.corpus.Corpus.window_frames`.
* :func:`foot_sliding_loss`: the mean squared horizontal speed of the foot joints over the frame pairs the
  labels have in contact at both frames.
* :func:`excess_jerk_loss`: the mean amount by which the norm of the third difference of each predicted
  joint position exceeds the real one's at the same joint and frame (the benchmark's jitter is the mean
  norm of the same third difference: :func:`keyfill.learn.protocols.metrics.jitter`).

The loss functions take torch tensors (through their methods: the module imports no torch, so reading it
costs nothing where torch is absent).
"""

from __future__ import annotations

import numpy as np


def corpus_contacts(corpus) -> tuple[np.ndarray, np.ndarray]:
    """``(labels (N, n) bool, joints (n,) int64)``: the contact labels of each of the corpus's ``N`` frames
    (computed clip by clip, rows aligned with ``corpus.quats``), columns in the order of
    :func:`keyfill.characters.feet.contact_joints` (``foot_l, toe_l, foot_r, toe_r``), and those joints. A
    skeleton without recognisable legs gives ``n = 0`` columns."""
    from keyfill.characters.feet import contact_joints, contacts
    from keyfill.characters.retarget import make_rig
    from keyfill.errors import KeyfillError
    from keyfill.learn.windows import window_motion

    try:
        rig = make_rig(corpus.skeleton)
        joints = np.array([j for _, j in contact_joints(rig)], dtype=np.int64)
    except KeyfillError:
        return np.zeros((len(corpus.quats), 0), dtype=bool), np.zeros(0, dtype=np.int64)
    parts = [contacts(window_motion(corpus.skeleton, *corpus.clip(i), float(corpus.fps)), rig)
             for i in range(len(corpus))]
    labels = np.concatenate(parts) if parts else np.zeros((0, len(joints)), dtype=bool)
    return labels.astype(bool), joints


def foot_sliding_loss(feet, contact, fps: float, up: int, pairs=None):
    """Mean squared horizontal speed (units of ``feet`` per second, squared) of the foot joints over the frame
    pairs ``(t, t + 1)`` in contact at both frames; 0 (still part of the graph) when there is none.

    Args:
        feet: ``(B, T, n, 3)`` world positions of the ``n`` contact joints.
        contact: ``(B, T, n)`` bool labels of the real motion.
        fps: frames per second; up: the up axis index (1 for Y, 2 for Z).
        pairs: optional ``(B, T - 1)`` weights of the frame pairs (e.g. 0 where a frame carries no loss).
    """
    ground = [a for a in range(3) if a != up]
    v = (feet[:, 1:, :, ground] - feet[:, :-1, :, ground]) * fps  # (B, T - 1, n, 2)
    w = (contact[:, 1:] & contact[:, :-1]).to(v.dtype)  # (B, T - 1, n)
    if pairs is not None:
        w = w * pairs[:, :, None]
    count = w.sum()
    if float(count) == 0:
        return (v * 0).sum()
    return ((v**2).sum(-1) * w).sum() / count


def third_difference(x):
    """``x[t + 3] - 3 x[t + 2] + 3 x[t + 1] - x[t]`` along axis 1: ``(B, T, ...)`` -> ``(B, T - 3, ...)``."""
    return x[:, 3:] - 3 * x[:, 2:-1] + 3 * x[:, 1:-2] - x[:, :-3]


def excess_jerk_loss(pred, true, scale: float, quads=None):
    """Mean over joints and frame quads of ``max(|d3 pred| - |d3 true|, 0) * scale`` (``d3``:
    :func:`third_difference`, norms over xyz); 0 (still part of the graph) without a quad.

    One-sided on purpose: the prediction pays for every bit of jerk the real motion does not have at that
    joint and frame, and nothing for being smoother (a two-sided ``(|d3 pred| - |d3 true|)^2`` would ask for
    jerk of the real size but any direction, i.e. noise); per element, so real impacts (a heel strike) in the
    truth cost nothing where the prediction has them too. Linear in the excess, so it reads as the jitter
    added beyond the real clip's, in the benchmark's units with ``scale = fps**3 * meters_per_unit`` (m/s^3).

    Args:
        pred, true: ``(B, T, J, 3)`` world joint positions.
        scale: multiplies the third differences (units, see above).
        quads: optional ``(B, T - 3)`` weights of the 4-frame spans (0 where one of the frames carries no loss).
    """
    d3p = (third_difference(pred) ** 2).sum(-1).clamp(min=1e-12).sqrt()  # (B, T - 3, J); the clamp keeps
    d3t = (third_difference(true) ** 2).sum(-1).sqrt()  # the gradient of a still joint finite
    excess = (d3p - d3t).clamp(min=0)
    J = pred.shape[-2]
    if quads is None:
        return excess.mean() * scale
    count = quads.sum() * J
    if float(count) == 0:
        return (excess * 0).sum()
    return (excess * quads[:, :, None]).sum() / count * scale
