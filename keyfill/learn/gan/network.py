"""The networks of Table 5: generator (encoder + decoder), discriminator, global path predictor.

All are 1-D fully convolutional over frames; tensors are ``(B, C, T)``. Every
hidden layer is a :class:`~keyfill.learn.gan.layers.ResidualConv` with
Table 5's kernel, stride, padding and residual ratio; the widths come from the
config (:data:`keyfill.learn.gan.config.PRESETS`). The last layer of the
decoder and of the path predictor is a plain convolution (Table 5 lists them
as residual layers; an activation on values that are unconstrained,
pre-``tanh`` angles and velocities, serves no purpose and a skip from 512 or
128 channels to a handful would need a projection of its own).

Lengths: the generator and the discriminator take ``T`` a multiple of 64, the
path predictor a multiple of 16 (:func:`pad_frames` pads by repeating the last frame).

* :class:`Generator`: ``(B, 6 J, T)`` dense keys (positions and distance mask,
  :mod:`keyfill.learn.gan.features`) -> ``(B, 6 + 3 D, T)`` RC-FK values. Six
  stride-2 layers encode to ``T / 64`` latent steps; per-step noise
  (``noise_dim`` channels) and a per-sequence style vector (``style_dim``
  channels; the Motion DNA hook, zero when not given) are joined to every latent
  step; the decoder goes back up with six transposed layers (or linear up-sampling), and
  its output may be a correction added to a base (the spline of ``GanConfig.base``). With a Motion DNA
  encoder (:class:`DnaEncoder`, ``generator.dna``) the style vector is made from
  representative poses.
* :class:`DnaEncoder`: ``(B, 3 (J - 1), P)`` root-free representative poses
  (:mod:`keyfill.learn.representative`), and which of the ``P`` are real ->
  ``(B, style_dim)``.
* :class:`Discriminator`: ``(B, 3 (J - 1), T)`` root-relative joint positions ->
  ``(B, T / 64)`` scores, one per overlapping sub-sequence (receptive field 190 frames).
* :class:`PathPredictor`: ``(B, 3 (J - 1), T)`` root-relative joint positions ->
  ``(B, 3, T)`` root velocities: entry ``t`` is ``root[t + 1] - root[t]``. Its
  output layer starts at zero (a fresh predictor says "standing still" rather
  than drifting at random).
"""

from __future__ import annotations

import torch
from torch import nn

from keyfill.learn.gan.layers import ResidualConv, receptive_field
from keyfill.learn.gan.rcfk import RCFK

#: (kernel, stride, pad, transpose) of the hidden layers, and their residual ratios (Table 5)
ENCODER = [(4, 2, 1, False)] * 6
ENCODER_RATIOS = [1 / 1, 1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6]
DECODER = [(1, 1, 0, False), (3, 1, 1, False)] + [(4, 2, 1, True), (3, 1, 1, False)] * 5 + [(4, 2, 1, True)]
DECODER_RATIOS = [1, 1 / 1.4, 1 / 1.6, 1 / 2.2, 1 / 2.8, 1 / 3.6, 1 / 4.6, 1 / 5.8, 1 / 7.2, 1 / 8.8, 1 / 10.6,
                  1 / 12.6, 1 / 14.8]
DECODER_OUT = (3, 1, 1)  # res_14's kernel, stride, pad
DISCRIMINATOR = [(4, 2, 1, False)] * 6
DISCRIMINATOR_RATIOS = [1 / 1, 1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6]
PATH = [(12, 2, 5, False)] * 4 + [(8, 2, 3, True)] * 4
PATH_RATIOS = [1 / n for n in range(1, 9)]
PATH_OUT = (5, 1, 2)
GENERATOR_MULTIPLE, PATH_MULTIPLE = 64, 16
#: the 6D vector of the identity rotation, added to the decoder's root output so that zero means "no turn"
IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


def _stack(c_in: int, widths, specs, ratios, form: str = "printed", upsampling: str = "transposed") -> nn.Sequential:
    layers = []
    for w, (k, s, p, t), r in zip(widths, specs, ratios):
        layers.append(ResidualConv(c_in, w, k, s, p, r, transpose=t, form=form, upsampling=upsampling))
        c_in = w
    return nn.Sequential(*layers)


def pad_frames(x, multiple: int):
    """``x (B, C, T)`` padded at the end, repeating its last frame, to a multiple of ``multiple`` frames."""
    T = x.shape[-1]
    extra = (-T) % multiple
    if extra == 0:
        return x
    return torch.cat([x, x[..., -1:].expand(*x.shape[:-1], extra)], dim=-1)


def generator_receptive_field() -> int:
    """Frames one latent step at the bottleneck sees (318 with Table 5's layers: encoder plus res_1, res_2)."""
    return receptive_field([(k, s, t) for k, s, _, t in ENCODER + DECODER[:2]])


def discriminator_receptive_field() -> int:
    """Frames one discriminator score depends on (190)."""
    return receptive_field([(k, s, t) for k, s, _, t in DISCRIMINATOR])


class DnaEncoder(nn.Module):
    """The Motion DNA encoder (section 3.5.1, Table 5): a per-pose MLP shared by the poses, average pooling, linear.

    conv_1 (1x1) -> affine -> PReLU -> conv_2 (1x1) -> affine, over each pose; the mean
    over the real poses; a linear layer to ``style_dim`` channels (the "additional
    linear layer" of the text, which Table 5 leaves out).

    Args:
        channels: ``3 (J - 1)`` values of a root-free pose.
        width: hidden width (Table 5: 1024).
        style_dim: channels of the vector ``w``.
        normalise: layer-normalise ``w`` over its channels (``GanConfig.dna_norm``: zero mean, unit
            variance per sequence, no learned scale), so it reaches the decoder at the size of the
            encoder's features.
    """

    def __init__(self, channels: int, width: int, style_dim: int, normalise: bool = False):
        super().__init__()
        self.normalise = normalise
        self.conv1 = nn.Conv1d(channels, width, 1, bias=False)
        self.scale1, self.bias1 = nn.Parameter(torch.ones(width)), nn.Parameter(torch.zeros(width))
        self.act = nn.PReLU(width)
        self.conv2 = nn.Conv1d(width, width, 1, bias=False)
        self.scale2, self.bias2 = nn.Parameter(torch.ones(width)), nn.Parameter(torch.zeros(width))
        self.linear = nn.Linear(width, style_dim)

    def forward(self, poses, valid=None):
        """``poses (B, 3 (J - 1), P)`` metres, ``valid (B, P)`` bool (None: all) -> ``w (B, style_dim)``."""
        h = self.act(self.conv1(poses) * self.scale1[:, None] + self.bias1[:, None])
        h = self.conv2(h) * self.scale2[:, None] + self.bias2[:, None]
        if valid is None:
            pooled = h.mean(-1)
        else:
            m = valid.to(h.dtype)[:, None]
            pooled = (h * m).sum(-1) / m.sum(-1).clamp_min(1)
        w = self.linear(pooled)
        return nn.functional.layer_norm(w, w.shape[-1:]) if self.normalise else w


class Generator(nn.Module):
    """Encoder, latent joining, decoder, and the RC-FK layer (parameter-free) as ``self.rcfk``.

    Args:
        num_joints: ``J``; the input has ``6 J`` channels (and the base's ``rcfk.channels`` with ``base_input``).
        rcfk: the RC-FK layer of the skeleton; the output has ``rcfk.channels``.
        encoder, decoder: widths (6 and 13).
        noise_dim, style_dim: channels joined to every latent step.
        dna_width: hidden width of a :class:`DnaEncoder` (``self.dna``) making the style
            vector from representative poses; 0: none (the style is given directly).
        dna_norm: the encoder's ``normalise``.
        form, upsampling: of the residual layers (:class:`~keyfill.learn.gan.layers.ResidualConv`).
        output_init: ``"default"`` or ``"small"`` (``GanConfig.output_init``).
        base_input: the encoder reads the base beside the dense input (``GanConfig.base_input``).
    """

    def __init__(self, num_joints: int, rcfk: RCFK, encoder, decoder, noise_dim: int = 0, style_dim: int = 0,
                 dna_width: int = 0, form: str = "printed", upsampling: str = "transposed",
                 output_init: str = "default", dna_norm: bool = False, base_input: bool = False):
        super().__init__()
        self.num_joints = num_joints
        self.noise_dim, self.style_dim = noise_dim, style_dim
        if dna_width:
            self.dna = DnaEncoder(3 * (num_joints - 1), dna_width, style_dim, dna_norm)
        self.base_input = base_input
        self.encoder = _stack(6 * num_joints + rcfk.channels * base_input, encoder, ENCODER, ENCODER_RATIOS, form)
        self.decoder = _stack(encoder[-1] + noise_dim + style_dim, decoder, DECODER, DECODER_RATIOS, form, upsampling)
        k, s, p = DECODER_OUT
        self.output = nn.Conv1d(decoder[-1], rcfk.channels, k, s, p)
        if output_init in ("small", "zero"):  # pre-tanh angles near 0 (mid-range), or no change to a base
            with torch.no_grad():
                self.output.weight.mul_(0.1 if output_init == "small" else 0.0)
                self.output.bias.zero_()
        self.rcfk = rcfk
        self.register_buffer("identity_6d", torch.tensor(IDENTITY_6D), persistent=False)

    def forward(self, dense, noise=None, style=None, dna=None, dna_valid=None, base=None):
        """``dense (B, 6 J, T)`` -> ``(B, 6 + 3 D, T)``; ``noise (B, noise_dim, T / 64)``, ``style (B, style_dim)``.

        ``dna (B, P, J - 1, 3)`` root-free representative poses (metres) with ``dna_valid (B, P)``
        make the style through ``self.dna`` (instead of ``style``). Missing noise or style count as zeros.
        ``base (B, 6 + 3 D, T)``: values the output is added to (``GanConfig.base``,
        :func:`keyfill.learn.gan.spline_base.spline_values`); None: the identity root rotation. With
        ``base_input`` the encoder reads it too (then it is required).
        """
        B, _, T = dense.shape
        if T % GENERATOR_MULTIPLE:
            raise ValueError(f"the generator takes a multiple of {GENERATOR_MULTIPLE} frames, got {T}")
        if dna is not None:
            style = self.dna(dna.flatten(2).transpose(1, 2), dna_valid)
        if self.base_input and base is None:
            raise ValueError("this generator reads its base (base_input): give base")
        z = self.encoder(torch.cat([dense, base.to(dense.dtype)], dim=1) if self.base_input else dense)
        parts = [z]
        if self.noise_dim:
            parts.append(noise if noise is not None else z.new_zeros(B, self.noise_dim, z.shape[-1]))
        if self.style_dim:
            s = style if style is not None else z.new_zeros(B, self.style_dim)
            parts.append(s[:, :, None].expand(B, self.style_dim, z.shape[-1]))
        v = self.output(self.decoder(torch.cat(parts, dim=1)))
        if base is not None:
            return v + base
        root = v[:, :6] + self.identity_6d[:, None].to(v.dtype)
        return torch.cat([root, v[:, 6:]], dim=1)


class Discriminator(nn.Module):
    """Six strided residual layers and a 1x1 convolution to one score per 64 frames."""

    def __init__(self, channels: int, widths, form: str = "printed"):
        super().__init__()
        self.body = _stack(channels, widths, DISCRIMINATOR, DISCRIMINATOR_RATIOS, form)
        self.score = nn.Conv1d(widths[-1], 1, 1)

    def forward(self, x):
        """``x (B, 3 (J - 1), T)`` -> ``(B, T / 64)``."""
        if x.shape[-1] % GENERATOR_MULTIPLE:
            raise ValueError(f"the discriminator takes a multiple of {GENERATOR_MULTIPLE} frames, got {x.shape[-1]}")
        return self.score(self.body(x))[:, 0]


class PathPredictor(nn.Module):
    """Four strided and four transposed residual layers, then a convolution to 3 velocity channels."""

    def __init__(self, channels: int, widths):
        super().__init__()
        self.body = _stack(channels, widths, PATH, PATH_RATIOS)
        k, s, p = PATH_OUT
        self.output = nn.Conv1d(widths[-1], 3, k, s, p)
        nn.init.zeros_(self.output.weight)  # start from standing still: zero velocity, not random drift
        nn.init.zeros_(self.output.bias)

    def forward(self, x):
        """``x (B, 3 (J - 1), T)`` -> velocities ``(B, 3, T)``; any ``T``: padded to a multiple of 16 and cut back."""
        T = x.shape[-1]
        return self.output(self.body(pad_frames(x, PATH_MULTIPLE)))[..., :T]


def count_weights(module: nn.Module) -> int:
    """Number of trainable and frozen parameters (scalars) of ``module``."""
    return sum(p.numel() for p in module.parameters())


def joint_channels(positions):
    """``positions (B, T, J, 3)`` root-relative -> ``(B, 3 (J - 1), T)``, the input of D and the path predictor."""
    B, T, J, _ = positions.shape
    return positions[:, :, 1:].reshape(B, T, 3 * (J - 1)).transpose(1, 2)


def root_path(velocities, start=None):
    """Root positions ``(B, T, 3)`` from velocities ``(B, 3, T)`` (entry t is root[t+1] - root[t]); root[0] = start or 0."""
    v = velocities.transpose(1, 2)[:, :-1]
    path = torch.cat([torch.zeros_like(v[:, :1]), torch.cumsum(v, dim=1)], dim=1)
    return path if start is None else path + start[:, None]


