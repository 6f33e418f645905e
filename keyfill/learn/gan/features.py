"""The dense keyframe input format of the local motion generator (section 3.5, Fig. 4).

Every frame gets a copy of the pose of its nearest key, and the mask becomes a
distance transform: 0 at a key, elsewhere the number of frames to the nearest
key (divided by ``mask_scale`` to keep the input near unit size). A frame
exactly between two keys takes the earlier one. Frames before the first and
after the last key take that key.

A pose is ``(J, 3)``: row 0 the root's position (world axes, the sequence
re-centred so that the keys' mean ground position is the origin), rows 1.. the
joints' positions relative to the root (world axes), all in metres. The
generator's input is ``(6 J, T)``: the ``3 J`` pose values, then the mask
repeated for every coordinate (the paper's ``3 M`` mask channels, which leave
room for partial keys). With ``root="key-relative"`` (``GanConfig.root_input``)
the root's two ground coordinates are instead the nearest key's offset from the
straight line between the frame's two keys (0 at the keys, bounded by the
distance the gap covers), so the channels stay near unit size however far a
long sequence travels; the height stays as it is.

Partial-key models (``GanConfig.partial_keys``, section 5) take the *sparse*
format instead (:func:`sparse_input`, Fig. 4's top rows): the given coordinates
at the key frames and zero elsewhere, then a mask that is 1 where a coordinate
is given and 0 elsewhere, again ``(6 J, T)``. Coordinates are given per key,
joint and axis (``coords (K, J, 3)`` bool, :meth:`keyfill.motion.Keys.coordinate_mask`).
"""

from __future__ import annotations

import numpy as np


def nearest_key(num_frames: int, key_frames) -> tuple[np.ndarray, np.ndarray]:
    """``(index (T,) int, distance (T,) int)``: each frame's nearest key (its index in ``key_frames``) and the distance."""
    k = np.asarray(key_frames, dtype=np.int64)
    f = np.arange(num_frames)
    right = np.clip(np.searchsorted(k, f, side="left"), 0, len(k) - 1)
    left = np.clip(right - 1, 0, len(k) - 1)
    dl, dr = np.abs(f - k[left]), np.abs(k[right] - f)
    idx = np.where(dl <= dr, left, right)
    return idx, np.minimum(dl, dr)


def dense_input(num_frames: int, key_frames, key_poses, mask_scale: float = 64.0, root: str = "centred",
                up_axis: str = "Y") -> np.ndarray:
    """The generator input ``(6 J, T)`` float32 for keys at ``key_frames (K,)`` with ``key_poses (K, J, 3)``;
    ``root``: ``"centred"`` or ``"key-relative"`` (the module docstring), ``up_axis`` the height's axis."""
    from keyfill.interpolate import segment_coordinates
    from keyfill.learn.windows import horizontal_axes

    idx, dist = nearest_key(num_frames, key_frames)
    poses = np.asarray(key_poses, dtype=np.float32)[idx]  # (T, J, 3)
    T, J = poses.shape[:2]
    if root == "key-relative":
        k = np.asarray(key_frames, dtype=np.int64)
        kr = np.asarray(key_poses, dtype=np.float64)[:, 0]
        if len(k) > 1:
            seg, u = segment_coordinates(T, k)  # frames past the last key: on it
            line = kr[seg] + u[:, None] * (kr[seg + 1] - kr[seg])  # (T, 3)
        else:
            line = np.broadcast_to(kr[0], (T, 3))
        h = list(horizontal_axes(up_axis))
        poses = poses.copy()
        poses[:, 0, h] = (kr[idx][:, h] - line[:, h]).astype(np.float32)
    pos = poses.reshape(T, 3 * J).T
    mask = np.broadcast_to((dist / mask_scale).astype(np.float32), (3 * J, T))
    return np.concatenate([pos, mask], axis=0)


def sparse_input(num_frames: int, key_frames, key_poses, coords) -> np.ndarray:
    """The sparse generator input ``(6 J, T)`` float32: ``key_poses (K, J, 3)`` where ``coords (K, J, 3)`` gives them."""
    key_poses = np.asarray(key_poses, dtype=np.float32)
    _K, J = key_poses.shape[:2]
    pos = np.zeros((num_frames, J, 3), np.float32)
    mask = np.zeros((num_frames, J, 3), np.float32)
    pos[key_frames] = np.where(coords, key_poses, 0.0)
    mask[key_frames] = coords
    return np.concatenate([pos.reshape(num_frames, 3 * J).T, mask.reshape(num_frames, 3 * J).T], axis=0)


def centre_keys(key_poses: np.ndarray, up_axis: str = "Y", coords=None) -> tuple[np.ndarray, np.ndarray]:
    """``(poses, shift (3,))``: key poses ``(K, J, 3)`` with the keys' mean ground position of the root moved to 0.

    Only the two ground axes move (the height stays); ``shift`` is what was
    subtracted. With partial keys (``coords (K, J, 3)`` bool) each ground axis is
    centred on the keys that give the root's coordinate on it (not moved when none does).
    """
    from keyfill.learn.windows import horizontal_axes

    h = list(horizontal_axes(up_axis))
    shift = np.zeros(3)
    if coords is None:
        shift[h] = np.asarray(key_poses)[:, 0, h].mean(axis=0)
    else:
        given = np.asarray(coords)[:, 0]
        for a in h:
            if given[:, a].any():
                shift[a] = np.asarray(key_poses)[given[:, a], 0, a].mean()
    out = np.array(key_poses, dtype=np.float64)
    out[:, 0] -= shift
    return out, shift
