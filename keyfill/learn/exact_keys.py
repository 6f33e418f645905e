"""Make a predicted motion hit its keys exactly, with a smooth correction.

Learned in-betweening leaves a small residual at the keys. :func:`snap_to_keys`
measures it at every key (translation difference, and the rotation that takes
the predicted local rotation to the key's) and spreads it over the frames
between two keys with smoothstep weights ``3u^2 - 2u^3``: the correction is
the full residual at each key and has zero slope there, so the corrected curve
keeps the prediction's velocity at the keys. Frames at keys are then copied
from the source, so they are bit-identical to the input.

Partial keys (:attr:`keyfill.motion.Keys.partial`) fix only the local channels
they give (:meth:`keyfill.motion.Keys.channel_masks`): a keyed joint's residual
is spread as above, an unkeyed one counts as a zero residual at that key, so it
stays as predicted there and is corrected only by its keyed neighbours' share;
at a key frame only the keyed channels are copied from the source.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.interpolate import in_blocks, segment_coordinates
from keyfill.motion import Keys, Motion


def snap_to_keys(pred: Motion, source: Motion, keys: Keys, in_place: bool = False) -> tuple[Motion, dict]:
    """Correct ``pred`` so that its frames at ``keys`` equal ``source``'s.

    Args:
        pred: the predicted motion, ``F`` frames; with ``in_place``, its arrays become the result's (for a
            caller that made them and lets go of ``pred``: a long take needs no second copy).
        source: the motion whose key frames are the truth (same skeleton, ``F`` frames; only its key
            frames are read).
        keys: key frames (at least 2); partial keys correct only the channels they give.

    Returns:
        ``(corrected motion, report)``, where the report gives the largest
        residual removed: ``key_residual_position`` (file units) and
        ``key_residual_rotation_rad`` (partial keys: and ``exact_channels``). The correction is made a
        block of frames at a time (:func:`keyfill.interpolate.in_blocks`): memory is the result's arrays.
    """
    k = keys.frames
    res_pos = source.positions[k] - pred.positions[k]  # (K, J, 3)
    res_rot = R.quat_mul(source.rotations[k], R.quat_conjugate(pred.rotations[k]))  # (K, J, 4)
    angle = R.quat_angle(source.rotations[k], pred.rotations[k])  # (K, J)
    if keys.partial:  # residuals of unkeyed channels count as zero
        rot_mask, pos_mask = keys.channel_masks(pred.skeleton)  # (K, J), (K, J, 3)
        res_pos = np.where(pos_mask, res_pos, 0.0)
        res_rot = np.where(rot_mask[..., None], res_rot, np.array([1.0, 0.0, 0.0, 0.0]))
        angle = np.where(rot_mask, angle, 0.0)
    s, u = segment_coordinates(pred.num_frames, k)
    w_all = 3 * u**2 - 2 * u**3

    def frames(a, b):
        ss, w = s[a:b], w_all[a:b, None]
        pos = pred.positions[a:b] + (1 - w[..., None]) * res_pos[ss] + w[..., None] * res_pos[ss + 1]
        corr = R.quat_slerp(res_rot[ss], res_rot[ss + 1], np.broadcast_to(w, res_rot[ss].shape[:2]))
        return R.quat_normalize(R.quat_mul(corr, pred.rotations[a:b])), pos

    rot, pos = in_blocks(pred.num_frames, frames, (pred.rotations, pred.positions) if in_place else None)
    report = {"key_residual_position": float(np.abs(res_pos).max(initial=0.0)),
              "key_residual_rotation_rad": float(angle.max(initial=0.0))}
    if keys.partial:
        rot[k] = np.where(rot_mask[..., None], source.rotations[k], rot[k])
        pos[k] = np.where(pos_mask, source.positions[k], pos[k])
        report["exact_channels"] = ("keyed joints' rotations and translations" if keys.given == "pose"
                                    else "the given translation coordinates of keyed joints with position channels")
    else:
        rot[k] = source.rotations[k]
        pos[k] = source.positions[k]
    return pred.replace(rotations=rot, positions=pos, keys=keys), report


def key_residual(pred: Motion, source: Motion, keys: Keys) -> dict:
    """The report of :func:`snap_to_keys` without the correction: how far ``pred``'s frames at ``keys`` are from
    ``source``'s (only the channels partial keys give), reading the key frames alone."""
    k = keys.frames
    res_pos = source.positions[k] - pred.positions[k]
    angle = R.quat_angle(source.rotations[k], pred.rotations[k])
    if keys.partial:
        rot_mask, pos_mask = keys.channel_masks(pred.skeleton)
        res_pos, angle = np.where(pos_mask, res_pos, 0.0), np.where(rot_mask, angle, 0.0)
    return {"key_residual_position": float(np.abs(res_pos).max(initial=0.0)),
            "key_residual_rotation_rad": float(angle.max(initial=0.0))}
