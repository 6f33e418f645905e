"""The transformer network (section 3.1 of Duan et al. 2021) and its training losses (Eqs. 12-15), in torch.

:class:`MotionTransformer`: Conv1d -> + mixture embedding -> BERT encoder -> Conv1d, with the residual
connection to the pre-filled input described in :mod:`keyfill.learn.transformer.model`.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from keyfill import rotations as R
from keyfill.errors import ModelError
from keyfill.learn.transformer.config import ModelConfig
from keyfill.learn.transformer.features import IGNORED, KEY, Features


class MotionTransformer(nn.Module):
    """Conv1d -> + mixture embedding -> BERT encoder -> Conv1d (section 3.1).

    ``features``: the size of a frame's feature vector (:class:`~keyfill.learn.transformer.features.Features`).
    """

    def __init__(self, features: int, cfg: ModelConfig):
        super().__init__()
        self.cfg = cfg
        self.input = nn.Conv1d(input_size(features, cfg), cfg.d_model, kernel_size=3, padding=1)
        self.position = nn.Embedding(cfg.max_frames, cfg.d_model)
        self.keyframe = nn.Embedding(3, cfg.d_model)
        if cfg.key_distances:
            self.since_key = nn.Embedding(cfg.max_frames, cfg.d_model)
            self.until_key = nn.Embedding(cfg.max_frames, cfg.d_model)
            nn.init.zeros_(self.since_key.weight)
            nn.init.zeros_(self.until_key.weight)
        layer = nn.TransformerEncoderLayer(
            cfg.d_model, cfg.heads, cfg.ffn, cfg.dropout, activation="gelu", batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.output = nn.Conv1d(cfg.d_model, features, kernel_size=3, padding=1)
        if cfg.residual:  # start as the interpolation it corrects
            nn.init.zeros_(self.output.weight)
            nn.init.zeros_(self.output.bias)

    def embed(self, kinds):
        """The mixture embedding ``(B, T, d_model)`` of frame kinds ``(B, T)``."""
        T = kinds.shape[-1]
        pos = torch.arange(T, device=kinds.device)
        out = self.position(pos) + self.keyframe(kinds)
        if self.cfg.key_distances:
            since, until = key_distances(kinds, self.cfg.max_frames - 1)
            out = out + self.since_key(since) + self.until_key(until)
        return out

    def forward(self, x, kinds):
        """``x (B, T, F)`` pre-filled features, ``kinds (B, T)`` -> ``(B, T, F)`` completed features."""
        T = x.shape[1]
        if T > self.cfg.max_frames:
            raise ModelError(f"{T} frames do not fit this model's {self.cfg.max_frames}-frame window")
        h = self.input(network_input(x, kinds, self.cfg).transpose(1, 2)).transpose(1, 2) + self.embed(kinds)
        h = self.encoder(h)
        y = self.output(h.transpose(1, 2)).transpose(1, 2)
        return x + y if self.cfg.residual else y


def input_size(features: int, cfg: ModelConfig) -> int:
    """Channels per frame of :func:`network_input` for ``features`` per frame."""
    return features * (2 if cfg.velocity_input else 1) + (cfg.unknown_input == "zero")


def network_input(x, kinds, cfg: ModelConfig):
    """What the network reads, ``(B, T, input_size)``, from pre-filled features ``x (B, T, F)`` and kinds ``(B, T)``.

    In this order: the features (with ``unknown_input`` ``"zero"``: zero on every frame that is not a key);
    with ``velocity_input`` each frame's features minus the previous frame's (0 on the first frame and, with
    zeros, wherever either frame is not a key); with ``"zero"`` a mask channel, 1 on keys and 0 elsewhere.
    With neither setting: ``x`` itself.
    """
    zero = cfg.unknown_input == "zero"
    known = (kinds == KEY).unsqueeze(-1).to(x.dtype)  # (B, T, 1)
    seen = x * known if zero else x
    parts = [seen]
    if cfg.velocity_input:
        step = seen[:, 1:] - seen[:, :-1]
        if zero:
            step = step * known[:, 1:] * known[:, :-1]
        parts.append(torch.cat([torch.zeros_like(seen[:, :1]), step], dim=1))
    if zero:
        parts.append(known)
    return torch.cat(parts, dim=-1) if len(parts) > 1 else seen


def input_channels(features: int, cfg: ModelConfig) -> dict:
    """Where each part of :func:`network_input` lies: ``{"features" | "velocity" | "mask": slice}``."""
    parts = {"features": slice(0, features)}
    if cfg.velocity_input:
        parts["velocity"] = slice(features, 2 * features)
    if cfg.unknown_input == "zero":
        parts["mask"] = slice(input_size(features, cfg) - 1, input_size(features, cfg))
    return parts


def widen_input(state: dict, features: int, old: ModelConfig, new: ModelConfig) -> dict:
    """``state`` (a network's tensors under ``old``) with its input layer laid out for ``new``'s input: the
    weights of each part both read are kept, those of a part only ``new`` reads start at zero, so a model
    fine-tuned with velocities added starts as the model it tunes (``--init``)."""
    weight = state["input.weight"]  # (d_model, channels, 3)
    have, want = input_channels(features, old), input_channels(features, new)
    wide = weight.new_zeros((weight.shape[0], input_size(features, new), weight.shape[2]))
    for name, where in want.items():
        if name in have:
            wide[:, where] = weight[:, have[name]]
    return {**state, "input.weight": wide}


def key_distances(kinds, limit: int):
    """``(since, until)``, each ``(B, T)`` int64: frames from the last key at or before each frame and to the
    next key at or after it (0 on a key), ``limit`` where there is none or it is farther."""
    T = kinds.shape[-1]
    t = torch.arange(T, device=kinds.device)
    d = t[:, None] - t[None, :]  # (T, T): frame i minus frame j
    key = (kinds == KEY)[:, None, :]  # (B, 1, T): frame j is a key
    far = torch.full((), limit, dtype=d.dtype, device=d.device)
    since = torch.where(key & (d >= 0), d, far).amin(-1).clamp(max=limit)
    until = torch.where(key & (d <= 0), -d, far).amin(-1).clamp(max=limit)
    return since, until


def build_network(features: int, cfg: ModelConfig):
    """A fresh :class:`MotionTransformer` torch module (weights from torch's current generator)."""
    return MotionTransformer(features, cfg)


# --- losses ----------------------------------------------------------------------


def losses(feat: Features, pred, target, gt_quats, gt_root, kinds, cfg: ModelConfig) -> dict:
    """The training losses (Eqs. 12-15) over key and unknown frames (torch).

    Args:
        pred, target: ``(B, T, F)`` predicted and true features.
        gt_quats, gt_root: the true local pose ``(B, T, J, 4)``, ``(B, T, 3)``.
        kinds: ``(B, T)`` frame kinds; IGNORED frames carry no loss.

    Returns ``{"total", "position", "rotation", "kinematics"[, "output_fk"]}`` (scalars).
    """
    w = (kinds != IGNORED).to(pred.dtype)  # (B, T)
    norm = w.sum().clamp(min=1)
    p_pos, p_q = feat.split(pred)
    t_pos, t_q = feat.split(target)
    std = feat._stats(pred)[1]
    pos_l = ((p_pos - t_pos).abs() / std).mean(-1)
    rot_l = (p_q - t_q).abs().mean((-1, -2))
    scale = float(np.mean(feat.pos_std))
    if feat.coordinates == "global":
        # IK loss: bone offsets recovered from the predicted global pose (Eq. 14).
        J = feat.num_joints
        gp = p_pos.reshape(p_pos.shape[:-1] + (J, 3))
        par = torch.as_tensor(feat.parents[1:], device=pred.device)
        local = R.quat_rotate(R.quat_conjugate(p_q[..., par, :]), gp[..., 1:, :] - gp[..., par, :])
        off = torch.as_tensor(feat.offsets[1:], dtype=pred.dtype, device=pred.device)
        kin_l = (local - off).abs().mean((-1, -2)) / scale
    else:
        # FK loss: global positions of the predicted local pose (Eq. 13).
        _, gp = feat.global_pose(p_q, p_pos)
        _, tp = feat.global_pose(gt_quats, gt_root)
        kin_l = (gp - tp).abs().mean((-1, -2)) / scale
    out = {
        "position": (pos_l * w).sum() / norm,
        "rotation": (rot_l * w).sum() / norm,
        "kinematics": (kin_l * w).sum() / norm,
    }
    out["total"] = out["position"] + cfg.rotation_weight * out["rotation"] + cfg.kinematics_weight * out["kinematics"]
    if cfg.fk_weight and feat.coordinates == "global":
        # FK of the decoded output: what the model's user (and L2P) gets.
        dq, droot = feat.decode(pred)
        _, gp_out = feat.global_pose(dq, droot)
        _, gp_true = feat.global_pose(gt_quats, gt_root)
        fk_l = (gp_out - gp_true).abs().mean((-1, -2)) / scale
        out["output_fk"] = (fk_l * w).sum() / norm
        out["total"] = out["total"] + cfg.fk_weight * out["output_fk"]
    return out
