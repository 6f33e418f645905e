"""The losses of Zhou et al. 2020 (torch): Eqs. 5, 7, 8, 10 and the Motion DNA losses, Eqs. 11-12.

Shapes: velocities ``(B, 3, T)`` (entry ``t`` is ``root[t + 1] - root[t]``, the
last one unused), root paths ``(B, T, 3)``, joint positions ``(B, T, J, 3)``,
key masks ``(B, T)`` bool, or for partial keys coordinate masks ``(B, T, J, 3)``
bool (which coordinates each key gives), root-free poses ``(B, T, J - 1, 3)``.
Positions are in whatever unit the caller gives (keyfill's networks work in
metres), and the losses are in that unit squared.
"""

from __future__ import annotations

import itertools

import torch

#: Eq. 5: displacements over 1, 2, 4, ..., 128 frames
SCALES = tuple(2**q for q in range(8))
#: Eqs. 7-8: labels of real and fake sub-sequences, and the generator's target
REAL, FAKE, GENERATOR_TARGET = 1.0, -1.0, 0.2361


def displacement_loss(velocities, root, lengths=None, scales=SCALES):
    """Eq. 5, the multi-scale root displacement loss of the global path predictor.

    For each interval ``n`` in ``scales``, the mean over ``t`` of
    ``|| sum_{i=t}^{t+n-1} v_i - (root[t+n] - root[t]) ||^2``, then the mean over
    the intervals. (Eq. 4 sums ``i = t0 .. t``, one term too many for a
    displacement from ``t0`` to ``t``; the sum here has exactly ``n`` terms, as
    the text means.) Intervals not shorter than a sequence have no terms; the
    mean is over the intervals that have some.

    Args:
        velocities: ``(B, 3, T)`` predicted root velocities.
        root: ``(B, T, 3)`` true root positions.
        lengths: ``(B,)`` valid frames per row (rows are padded at the end), or None for all ``T``.

    Each row's value is exactly Eq. 5 with ``1 / (N - n)`` per interval (its own
    ``N``); the batch's loss is the mean over rows, so shards of a batch
    weighted by their rows give the whole batch's loss.
    """
    B, _, T = velocities.shape
    v = velocities.transpose(1, 2)[:, : T - 1]
    cum = torch.cat([torch.zeros_like(v[:, :1]), torch.cumsum(v, dim=1)], dim=1)  # (B, T, 3): predicted root - root[0]
    if lengths is None:
        lengths = torch.full((B,), T, dtype=torch.long, device=velocities.device)
    lengths = torch.as_tensor(lengths, device=velocities.device)
    total = torch.zeros(B, dtype=velocities.dtype, device=velocities.device)
    fitting = torch.zeros(B, dtype=velocities.dtype, device=velocities.device)
    for n in scales:
        if n >= T:
            continue
        err = (cum[:, n:] - cum[:, :-n]) - (root[:, n:] - root[:, :-n])  # (B, T - n, 3), t = 0 .. T-n-1
        valid = ((torch.arange(T - n, device=v.device)[None] + n) < lengths[:, None]).to(err.dtype)
        count = valid.sum(1)  # N - n per row
        fits = count > 0
        total = total + torch.where(fits, ((err**2).sum(-1) * valid).sum(1) / count.clamp_min(1), 0)
        fitting = fitting + fits.to(total.dtype)
    return (total / fitting.clamp_min(1)).mean()


def discriminator_loss(real_scores, fake_scores):
    """Eq. 7 (least-squares GAN): ``mean((y_real - 1)^2) + mean((y_fake + 1)^2)``."""
    return ((real_scores - REAL) ** 2).mean() + ((fake_scores - FAKE) ** 2).mean()


def generator_loss(fake_scores):
    """Eq. 8: ``mean((y_fake - 0.2361)^2)``."""
    return ((fake_scores - GENERATOR_TARGET) ** 2).mean()


def key_joint_loss(positions, key_positions, key_mask):
    """Keyframe loss on the local joints: per row, the mean over its key frames and non-root joints of the
    squared distance; then the mean over rows.

    ``positions``, ``key_positions``: ``(B, T, J, 3)`` root-relative; joint 0 is skipped.
    """
    d = ((positions[:, :, 1:] - key_positions[:, :, 1:]) ** 2).sum(-1).mean(-1)  # (B, T)
    m = key_mask.to(d.dtype)
    return ((d * m).sum(1) / m.sum(1).clamp_min(1)).mean()


def masked_key_joint_loss(positions, key_positions, coords):
    """:func:`key_joint_loss` over the coordinates partial keys give (``coords (B, T, J, 3)`` bool).

    Per row, the summed squared differences of the given coordinates of joints 1..,
    divided by a third of their number (so with every coordinate given it is
    :func:`key_joint_loss`); rows giving no joint count as zero.
    """
    m = coords[:, :, 1:].to(positions.dtype)
    d = ((positions[:, :, 1:] - key_positions[:, :, 1:]) ** 2 * m).sum((1, 2, 3))
    return (d / (m.sum((1, 2, 3)) / 3).clamp_min(1)).mean()


def masked_key_root_loss(root, key_root, coords):
    """Eq. 10 over the root coordinates partial keys give (``coords (B, T, 3)`` bool).

    Each axis is re-centred on its mean over the keys that give it; the sum of the
    squared differences is divided by a third of the given coordinates (so with
    every coordinate given it is :func:`key_root_loss`).
    """
    m = coords.to(root.dtype)
    n = m.sum(1, keepdim=True).clamp_min(1)  # (B, 1, 3) keys per axis
    c = (root * m).sum(1, keepdim=True) / n
    ck = (key_root * m).sum(1, keepdim=True) / n
    d = (((root - c) - (key_root - ck)) ** 2 * m).sum((1, 2))
    return (d / (m.sum((1, 2)) / 3).clamp_min(1)).mean()


def root_free(quats, relative):
    """The paper's ``Lambda``: ``relative (B, T, J, 3)`` root-relative world-axis positions turned into the root's
    axes by the inverse of the root rotation ``quats[:, :, 0] (B, T, 4)`` -> ``(B, T, J - 1, 3)``."""
    from keyfill import rotations as R

    inv = R.quat_conjugate(quats[:, :, :1]).expand(*relative[:, :, 1:].shape[:-1], 4)
    return R.quat_rotate(inv, relative[:, :, 1:])


def pose_errors(poses, reps, squared: bool = True):
    """``(T, P)``: per frame and representative pose, the mean over joints of the squared distance (or the
    distance, ``squared=False``) between ``poses (T, J - 1, 3)`` and ``reps (P, J - 1, 3)``."""
    d = ((poses[:, None] - reps[None]) ** 2).sum(-1)  # (T, P, J - 1)
    return d.mean(-1) if squared else d.clamp_min(1e-12).sqrt().mean(-1)


def dna_losses(poses, reps, valid, key_mask, min_frames: int, squared: bool = True):
    """Eqs. 11 and 12: ``(L_DNA1, L_DNA2)`` for a batch.

    Args:
        poses: ``(B, T, J - 1, 3)`` root-free generated poses (:func:`root_free`).
        reps: ``(B, P, J - 1, 3)`` root-free representative poses; ``valid (B, P)`` bool marks the real ones.
        key_mask: ``(B, T)`` bool, the key frames that cut the sequence into intervals.
        min_frames: the 3 s of the paper in frames: an interval of ``N_k >= min_frames``
            frames holds ``floor(N_k / min_frames)`` poses.
        squared: the loss (mean squared joint distance); ``False`` gives the error in
            distance units (mean joint distance), as the paper reports it in cm.

    Eq. 11, per row: the mean over representative poses of the error of the closest
    generated frame. Eq. 12, per row: for each interval ``[k_i, k_{i+1})`` between
    consecutive keys long enough, each frame's error to its closest representative
    pose, the ``floor(N_k / min_frames)`` lowest of them collected over the row and
    averaged. The batch's values are the means over the rows that have terms (zero
    when none has).
    """
    l1, l2 = [], []
    for b in range(poses.shape[0]):
        r = reps[b][valid[b]]
        if len(r) == 0:
            continue
        err = pose_errors(poses[b], r, squared)  # (T, P_b)
        l1.append(err.min(0).values.mean())
        keys = torch.nonzero(key_mask[b]).flatten().tolist()
        picked = []
        for a, c in itertools.pairwise(keys):
            count = (c - a) // min_frames
            if count:
                picked.append(torch.topk(err[a:c].min(1).values, count, largest=False).values)
        if picked:
            l2.append(torch.cat(picked).mean())
    zero = poses.sum() * 0
    return (torch.stack(l1).mean() if l1 else zero), (torch.stack(l2).mean() if l2 else zero)


def key_root_loss(root, key_root, key_mask):
    """Eq. 10: the root path at the keys after re-centring both paths on their mean over the keys.

    ``root``, ``key_root``: ``(B, T, 3)``. Per row,
    ``1/N' sum_{t in keys} ||(root_t - mean) - (key_t - key mean)||^2``; the mean over rows.
    """
    m = key_mask.to(root.dtype)[..., None]  # (B, T, 1)
    n = m.sum(1, keepdim=True).clamp_min(1)
    c = (root * m).sum(1, keepdim=True) / n
    ck = (key_root * m).sum(1, keepdim=True) / n
    d = (((root - c) - (key_root - ck)) ** 2 * m).sum((1, 2)) / n[:, 0, 0]
    return d.mean()


def _form(squared, form: str):
    """``squared`` distances as they are (``"squared"``), or their square roots (``"distance"``; ``GanConfig.loss_form``,
    kept off the root's infinite slope at 0)."""
    return squared if form == "squared" else (squared + 1e-8).sqrt()


def reconstruction_loss(positions, truth, key_mask, valid, form: str = "squared"):
    """The second recipe's supervised term (not in the paper): per row, the mean over its valid frames between
    keys and its non-root joints of the squared distance to the ground truth (``form`` ``"distance"``: of the
    distance); the mean over rows with such frames (zero when none has).

    ``positions``, ``truth``: ``(B, T, J, 3)`` root-relative (joint 0 skipped); ``key_mask``, ``valid``: ``(B, T)``
    bool (valid: frames that have a ground truth).
    """
    d = _form(((positions[:, :, 1:] - truth[:, :, 1:]) ** 2).sum(-1), form).mean(-1)  # (B, T)
    m = (valid & ~key_mask).to(d.dtype)
    n = m.sum(1)
    rows = n > 0
    if not bool(rows.any()):
        return positions.sum() * 0
    return ((d * m).sum(1)[rows] / n[rows]).mean()


def foot_sliding_loss(root, relative, joints, contact, fps: float, up: int, form: str = "squared"):
    """The foot-sliding term: the mean squared horizontal speed, (m/s)^2, of the foot joints over the frame pairs
    ``(t, t + 1)`` that the labels have in contact at both frames (zero when there is none); ``form``
    ``"distance"``: the mean speed, m/s.

    Args:
        root: ``(B, T, 3)`` root path; ``relative``: ``(B, T, J, 3)`` root-relative positions (world axes), metres.
        joints: ``(n,)`` the foot joints; ``contact``: ``(B, T, n)`` bool labels (ground truth).
        fps: frames per second; up: the up axis (1 for Y, 2 for Z).
    """
    world = root[:, :, None] + relative[:, :, joints]  # (B, T, n, 3)
    ground = [a for a in range(3) if a != up]
    v = (world[:, 1:, :, ground] - world[:, :-1, :, ground]) * fps  # (B, T - 1, n, 2)
    both = (contact[:, 1:] & contact[:, :-1]).to(v.dtype)
    count = both.sum()
    if float(count) == 0:
        return root.sum() * 0
    return (_form((v**2).sum(-1), form) * both).sum() / count
