"""Range-constrained forward kinematics, the RC-FK layer of section 3.3 (torch).

The generator's last layer gives, per frame, ``6 + 3 D`` unconstrained values
(``D`` driven joints, :mod:`keyfill.learn.gan.ranges`):

* the root's rotation in the continuous 6D representation (Zhou et al. 2019):
  two 3-vectors, made orthonormal by Gram-Schmidt, are the first two columns
  of the rotation matrix; the third is their cross product;
* three values ``v`` per driven joint, mapped into the joint's feasible range
  ``[alpha, beta]`` by ``u = alpha + (beta - alpha) * (tanh(v) + 1) / 2`` and
  used as intrinsic Euler angles in the joint's order.

The paper's Eq. 3 prints ``u = (alpha - beta) tanh(v) + (alpha - beta) / 2``.
With ``alpha < beta`` that spans ``[-3 (beta - alpha) / 2, (beta - alpha) / 2]``,
never ``[alpha, beta]``: a sign slip. This layer implements the map the text
means, ``u = (beta - alpha) / 2 * tanh(v) + (alpha + beta) / 2``, written as
``alpha + (beta - alpha) (tanh(v) + 1) / 2``: ``tanh`` = -1 gives ``alpha``,
+1 gives ``beta``, so the angles can never leave the range.

Forward kinematics then uses the skeleton's constant bone offsets, so bone
lengths are exact by construction. Joints that are not driven keep the
identity rotation here (``complete`` interpolates them).

Outputs are *root-relative* joint positions in world axes: the root at the
origin, the rest placed by the root's rotation and the local rotations. These
are the paper's ``T^joints``; the global path predictor adds the root path.
Positions are in the units of the offsets given (metres inside the networks).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from keyfill import rotations as R
from keyfill.kinematics import fk
from keyfill.learn.gan.ranges import JointRanges


def rotation_6d_to_matrix(x):
    """Rotation matrices ``(..., 3, 3)`` from 6D vectors ``(..., 6)`` (the first two columns, Gram-Schmidt)."""
    a, b = x[..., :3], x[..., 3:]
    c1 = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    b = b - (c1 * b).sum(-1, keepdim=True) * c1
    c2 = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    c3 = torch.cross(c1, c2, dim=-1)
    return torch.stack([c1, c2, c3], dim=-1)


def range_map(v, lo, hi):
    """``lo + (hi - lo) * (tanh(v) + 1) / 2``: any ``v`` into ``[lo, hi]`` (Eq. 3 as meant)."""
    return lo + (hi - lo) * (torch.tanh(v) + 1) * 0.5


def binomial_lowpass(x, order: int, dim: int):
    """``x`` filtered along ``dim`` with the binomial kernel of ``order`` (``order + 1`` taps, e.g. 4:
    ``[1, 4, 6, 4, 1] / 16``), the ends padded by repeating the first and last values; ``order`` 0 or 1
    returns ``x``. The kernel's weights are positive and sum to 1, so every output is a convex
    combination of inputs: values inside a box stay inside it. Order 4 removes the period-2 component
    (gain 0), keeps a quarter of the period-4 one and 82 % of a period of 10 frames.
    """
    half = order // 2
    if half == 0:
        return x
    k = torch.tensor([math.comb(2 * half, i) for i in range(2 * half + 1)], dtype=x.dtype, device=x.device)
    k = k / k.sum()
    moved = x.movedim(dim, -1)
    flat = moved.reshape(-1, 1, moved.shape[-1])
    padded = torch.cat([flat[..., :1].expand(-1, -1, half), flat, flat[..., -1:].expand(-1, -1, half)], dim=-1)
    out = torch.nn.functional.conv1d(padded, k.view(1, 1, -1))
    return out.reshape(moved.shape).movedim(-1, dim)


class RCFK(nn.Module):
    """The RC-FK layer: network output -> (local quaternions, root-relative joint positions).

    Args:
        parents: ``(J,)`` parent indices.
        offsets: ``(J, 3)`` constant bone offsets (joint 0's is ignored).
        ranges: the driven joints' orders and ranges.
    """

    def __init__(self, parents, offsets, ranges: JointRanges):
        super().__init__()
        self.parents = [int(p) for p in parents]
        self.num_joints = len(self.parents)
        off = torch.tensor(np.array(offsets, dtype=np.float64), dtype=torch.float32)
        off[0] = 0.0
        self.register_buffer("offsets", off, persistent=False)
        self.register_buffer("lo", torch.tensor(np.array(ranges.lo), dtype=torch.float32), persistent=False)
        self.register_buffer("hi", torch.tensor(np.array(ranges.hi), dtype=torch.float32), persistent=False)
        self.driven = [int(j) for j in ranges.driven]
        # driven joints grouped by order: (order, positions in the driven list, joint indices)
        self.groups = []
        for o in sorted(set(ranges.orders)):
            pos = [d for d, oo in enumerate(ranges.orders) if oo == o]
            self.groups.append((o, pos, [self.driven[d] for d in pos]))

    @property
    def channels(self) -> int:
        """Values per frame the layer takes: ``6 + 3 D``."""
        return 6 + 3 * len(self.driven)

    def angles(self, v):
        """Euler angles ``(B, T, D, 3)`` radians of the driven joints from ``v (B, channels, T)``."""
        B, _, T = v.shape
        raw = v[:, 6:].transpose(1, 2).reshape(B, T, -1, 3)
        return range_map(raw, self.lo, self.hi)

    def rotations(self, v, smoothing: int = 0):
        """Local unit quaternions ``(B, T, J, 4)`` from ``v (B, channels, T)`` (root first).

        ``smoothing`` > 1 low-passes the root's 6D values and the joints' range-mapped angles
        along time (:func:`binomial_lowpass` of that order) before they become rotations, so the
        angles stay inside their ranges.
        """
        B, C, T = v.shape
        if C != self.channels:
            raise ValueError(f"RC-FK takes {self.channels} channels, got {C}")
        six = binomial_lowpass(v[:, :6], smoothing, dim=2)
        root = R.quat_from_matrix(rotation_6d_to_matrix(six.transpose(1, 2)))  # (B, T, 4)
        ang = binomial_lowpass(self.angles(v), smoothing, dim=1)
        q = R.quat_identity((B, T, self.num_joints), like=v).clone()
        q[:, :, 0] = root
        for order, pos, joints in self.groups:
            q[:, :, joints] = R.euler_to_quat(ang[:, :, pos], order)
        return q

    def forward(self, v, smoothing: int = 0):
        """``v (B, 6 + 3 D, T)`` -> ``(quats (B, T, J, 4), positions (B, T, J, 3))``, the root at the origin
        (``smoothing``: see :meth:`rotations`)."""
        q = self.rotations(v, smoothing)
        B, T = q.shape[:2]
        local = self.offsets.to(q.dtype).expand(B, T, self.num_joints, 3)
        _, pos = fk(q, local, self.parents)
        return q, pos
