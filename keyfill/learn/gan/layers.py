"""The modified residual convolution of Eq. 6 and the batch regularisation loss of Eq. 9.

Tensors are ``(B, C, T)``: batch, channels, frames (``torch.nn.Conv1d`` layout).

Eq. 6, implemented as printed::

    x'          = conv(x)
    residual(x) = PReLU(affine(x')) + sqrt(1 - s) * skip(x)
    y           = sqrt(s) * residual(x) + sqrt(1 - s) * skip(x)

with the residual ratio ``s`` in (0, 1] (Table 5's ``ratio`` column; 1 means no
skip). Read literally, the skip path's gain is ``sqrt(s) sqrt(1 - s) + sqrt(1 - s)``,
above 1 for every ratio of Table 5 (1.21 at s = 1/2, 1.32 at 1/6), so activations grow
layer by layer (about 7x through the decoder of a fresh generator). ``form="variance"``
reads Eq. 6 as the variance-preserving blend it is evidently meant to be::

    y = sqrt(s) * PReLU(affine(x')) + sqrt(1 - s) * skip(x)

(the gains' squares sum to 1: two unit-variance, uncorrelated inputs give a
unit-variance output). That form also initialises its convolutions for unit gain
(He et al.'s normal initialisation for a PReLU of slope 0.25, and for the 1x1 skip
projection a linear one): with PyTorch's default, which shrinks each layer about
1.7x, a blend that no longer amplifies would fade to nothing over 19 layers. ``affine`` is a learned per-channel scale and bias, so the convolution
has no bias of its own. The paper does not say how the skip path follows a
layer that changes the length or the width; here ``skip`` resamples the length
(average pooling by the stride going down, linear interpolation by the stride
going up) and, when the width changes, applies a learned 1x1 convolution. A
layer with ``s = 1`` has no skip path at all.

Each layer keeps the batch statistics of its ``x'`` from the last forward pass
in training mode; :func:`batch_regularisation` sums Eq. 9 over the layers of a
network.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

EPS = 1e-5


class ResidualConv(nn.Module):
    """One modified residual layer (Eq. 6); ``transpose`` makes it a res_t (up-sampling) layer.

    Args:
        c_in, c_out: channels.
        kernel, stride, pad: of the (transposed) convolution.
        ratio: the residual ratio ``s`` in (0, 1].
        transpose: an up-sampling layer (length times ``stride``) instead of a strided one
            (length divided by ``stride``).
        form: ``"printed"`` or ``"variance"`` (the module docstring).
        upsampling: how an up-sampling layer up-samples: ``"transposed"`` (a transposed convolution of
            ``kernel``) or ``"linear"`` (linear interpolation by ``stride``, then a convolution of kernel 3:
            every output frame mixes its neighbours the same way, so no period-``stride`` ripple).
    """

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int, pad: int, ratio: float, transpose=False,
                 form: str = "printed", upsampling: str = "transposed"):
        super().__init__()
        if not 0 < ratio <= 1:
            raise ValueError(f"residual ratio must be in (0, 1], got {ratio}")
        self.resample = transpose and upsampling == "linear"
        if self.resample:
            self.conv = nn.Conv1d(c_in, c_out, 3, padding=1, bias=False)
        else:
            conv = nn.ConvTranspose1d if transpose else nn.Conv1d
            self.conv = conv(c_in, c_out, kernel, stride=stride, padding=pad, bias=False)
        self.scale = nn.Parameter(torch.ones(c_out))
        self.bias = nn.Parameter(torch.zeros(c_out))
        self.act = nn.PReLU(c_out)
        self.ratio = float(ratio)
        self.stride = stride
        self.transpose = transpose
        self.form = form
        self.project = nn.Conv1d(c_in, c_out, 1, bias=False) if ratio < 1 and c_in != c_out else None
        if form == "variance":  # unit gain per layer, so that the blend keeps unit-size activations
            nn.init.kaiming_normal_(self.conv.weight, a=0.25, nonlinearity="leaky_relu",
                                    mode="fan_out" if isinstance(self.conv, nn.ConvTranspose1d) else "fan_in")
            if self.project is not None:
                nn.init.kaiming_normal_(self.project.weight, nonlinearity="linear")
        self.stats: tuple[torch.Tensor, torch.Tensor] | None = None  # (mean (C,), std (C,)) of x' in training

    def skip(self, x):
        """``x`` resampled to this layer's output length and width."""
        if self.stride > 1:
            if self.transpose:
                x = F.interpolate(x, scale_factor=self.stride, mode="linear", align_corners=False)
            else:
                x = F.avg_pool1d(x, self.stride)
        return self.project(x) if self.project is not None else x

    def forward(self, x):
        """``x (B, c_in, T)`` -> ``(B, c_out, T')``."""
        h = self.conv(F.interpolate(x, scale_factor=self.stride, mode="linear", align_corners=False)
                      if self.resample else x)
        if self.training:
            dims = (0, 2)
            self.stats = (h.mean(dims), h.std(dims) if h.shape[0] * h.shape[2] > 1 else torch.ones_like(h[0, :, 0]))
        h = self.act(h * self.scale[:, None] + self.bias[:, None])
        if self.ratio >= 1:
            return h
        s = self.ratio
        sk = self.skip(x)
        if self.form == "variance":
            return math.sqrt(s) * h + math.sqrt(1 - s) * sk
        res = h + math.sqrt(1 - s) * sk
        return math.sqrt(s) * res + math.sqrt(1 - s) * sk


def batch_regularisation(module: nn.Module) -> torch.Tensor:
    """Eq. 9 over every :class:`ResidualConv` in ``module`` (after a training-mode forward pass).

    ``1/D * sum over layers of (||mean(x')||^2 + ||log std(x')||^2)``, the mean and
    standard deviation taken per channel over batch and frames, ``D`` the total
    number of channels. A scalar tensor (0 when no layer has statistics).
    """
    total, dims = None, 0
    for m in module.modules():
        if isinstance(m, ResidualConv) and m.stats is not None:
            mean, std = m.stats
            term = (mean**2).sum() + (torch.log(std + EPS) ** 2).sum()
            total = term if total is None else total + term
            dims += mean.numel()
    if total is None:
        return torch.zeros(())
    return total / dims


def clear_statistics(module: nn.Module) -> None:
    """Forget the batch statistics kept by the layers of ``module``."""
    for m in module.modules():
        if isinstance(m, ResidualConv):
            m.stats = None


def receptive_field(layers: list[tuple[int, int, bool]]) -> int:
    """Frames of input one output step depends on, for a stack of ``(kernel, stride, transpose)`` layers.

    Down-sampling layers widen it by ``(kernel - 1) * jump`` and multiply the
    jump (input frames per step) by the stride; an up-sampling layer of kernel
    ``k`` and stride ``s`` reaches ``ceil(k / s)`` input steps, so it widens by
    ``(ceil(k / s) - 1) * jump`` and divides the jump by ``s``. Table 5's encoder
    gives 190 frames, encoder plus the first two decoder layers 318 (the
    paper's bottleneck figure).
    """
    rf, jump = 1.0, 1.0
    for k, s, t in layers:
        if t:
            rf += (math.ceil(k / s) - 1) * jump
            jump /= s
        else:
            rf += (k - 1) * jump
            jump *= s
    return round(rf)
