"""What the transformer sees: key layouts, the canonical frame of a window, and the feature encoding.

* :func:`frame_kinds`: each frame of a window is a key, unknown (to fill) or
  ignored (outside the keys); the network embeds the kind.
* :func:`canonical_transform` / :func:`apply_transform`: a window is turned
  about the up axis and shifted on the ground so that its anchor key faces +X
  at the origin (:func:`anchor_frame`), and back.
* :class:`Features`: poses ``(quats (..., J, 4), root (..., 3))`` <-> the
  normalised feature vectors the network reads and writes (global or local
  coordinates, see :class:`keyfill.learn.transformer.model.ModelConfig`).

numpy and torch arrays both work (:mod:`keyfill.rotations` is generic); this
module imports no torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill import rotations as R
from keyfill.kinematics import fk
from keyfill.learn.windows import axis_vector, facing_rotation, horizontal_axes

KEY, UNKNOWN, IGNORED = 0, 1, 2


# --- key layouts ----------------------------------------------------------------


def frame_kinds(num_frames: int, keys) -> np.ndarray:
    """``(T,)`` int: KEY at key frames, UNKNOWN between the first and last key, IGNORED outside."""
    keys = np.asarray(keys, dtype=np.int64)
    kinds = np.full(num_frames, IGNORED, dtype=np.int64)
    if len(keys):
        kinds[keys[0] : keys[-1] + 1] = UNKNOWN
        kinds[keys] = KEY
    return kinds


def anchor_frame(keys) -> int:
    """The key whose facing defines the canonical frame: the last key before the first unknown frame."""
    keys = np.asarray(keys)
    gaps = np.flatnonzero(np.diff(keys) > 1)
    return int(keys[gaps[0]] if len(gaps) else keys[0])


def canonical_transform(quats: np.ndarray, root: np.ndarray, keys, facing_axis: str, up_axis: str = "Y"):
    """``(turn (B, 4), shift (B, 3))`` that put windows in the model's canonical frame.

    ``shift`` is the mean ground position of the root over the key frames,
    ``turn`` rotates about the up axis so that the root faces +X on the anchor
    key. Canonical root = ``turn * (root - shift)``, root rotation = ``turn * q``.
    """
    keys = np.asarray(keys)
    shift = np.zeros(root.shape[:1] + (3,))
    h = list(horizontal_axes(up_axis))
    shift[:, h] = root[:, keys][..., h].mean(axis=1)
    turn = R.quat_conjugate(facing_rotation(quats[:, anchor_frame(keys), 0], axis_vector(facing_axis), up_axis))
    return turn, shift


def apply_transform(quats: np.ndarray, root: np.ndarray, turn: np.ndarray, shift: np.ndarray, inverse=False):
    """Apply (or undo) a :func:`canonical_transform` to ``quats (B, T, J, 4)``, ``root (B, T, 3)``."""
    q = np.array(quats, dtype=np.float64)
    t = turn[:, None]
    if inverse:
        t = R.quat_conjugate(t)
        q[:, :, 0] = R.quat_mul(t, q[:, :, 0])
        return q, R.quat_rotate(t, root) + shift[:, None]
    q[:, :, 0] = R.quat_mul(t, q[:, :, 0])
    return q, R.quat_rotate(t, root - shift[:, None])


# --- features ------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Features:
    """Frames <-> feature vectors for one skeleton and coordinate system (numpy or torch).

    Attributes:
        coordinates: ``"global"``: ``J * 3`` normalised global positions, then
            ``J * 4`` global quaternions; ``"local"``: 3 normalised root
            coordinates, then ``J * 4`` local quaternions.
        parents: ``(J,)`` parent indices.
        offsets: ``(J, 3)`` constant bone offsets (file units).
        pos_mean, pos_std: ``(J * 3,)`` statistics of global joint positions
            in the canonical frame (the local features use the first three).
    """

    coordinates: str
    parents: np.ndarray
    offsets: np.ndarray
    pos_mean: np.ndarray
    pos_std: np.ndarray

    @property
    def num_joints(self) -> int:
        return len(self.parents)

    @property
    def size(self) -> int:
        J = self.num_joints
        return J * 7 if self.coordinates == "global" else 3 + J * 4

    def _like(self, a, like):
        if R._xp(like) is np:
            return np.asarray(a, dtype=like.dtype)
        import torch

        return torch.as_tensor(a, dtype=like.dtype, device=like.device)

    def _stats(self, like):
        n = 3 if self.coordinates == "local" else len(self.pos_mean)
        return self._like(self.pos_mean[:n], like), self._like(self.pos_std[:n], like)

    def global_pose(self, quats, root):
        """Global ``(quats, positions)`` from local quats ``(..., J, 4)`` and root ``(..., 3)``."""
        xp = R._xp(quats)
        off = self._like(self.offsets[1:], root)
        rest = xp.broadcast_to(off, root.shape[:-1] + off.shape) if xp is np else off.expand(root.shape[:-1] + off.shape)
        pos = xp.concatenate([root[..., None, :], rest], axis=-2)
        return fk(quats, pos, self.parents)

    def encode(self, quats, root):
        """``(B, T, size)`` features of local quats ``(B, T, J, 4)`` and root ``(B, T, 3)``."""
        xp = R._xp(quats)
        B, T = root.shape[:2]
        mean, std = self._stats(root)
        if self.coordinates == "global":
            gq, gp = self.global_pose(quats, root)
            return xp.concatenate([(gp.reshape(B, T, -1) - mean) / std, gq.reshape(B, T, -1)], axis=-1)
        return xp.concatenate([(root - mean) / std, quats.reshape(B, T, -1)], axis=-1)

    def split(self, x):
        """Features -> ``(positions or root (B, T, J*3 or 3), quats (B, T, J, 4) normalised)``."""
        J = self.num_joints
        n = J * 3 if self.coordinates == "global" else 3
        mean, std = self._stats(x)
        pos = x[..., :n] * std + mean
        q = x[..., n:].reshape(x.shape[:-1] + (J, 4))
        return pos, R.quat_normalize(q)

    def decode(self, x):
        """Features -> local ``(quats (B, T, J, 4), root (B, T, 3))`` (global: simplest IK)."""
        pos, q = self.split(x)
        if self.coordinates == "local":
            return q, pos
        par = np.asarray(self.parents)
        local = R.quat_mul(R.quat_conjugate(q[..., par[1:], :]), q[..., 1:, :])
        return R._xp(q).concatenate([q[..., :1, :], local], axis=-2), pos[..., :3]
