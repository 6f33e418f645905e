"""Keyframe-conditioned autoregressive networks for the hopping lamp (Zhang & van de Panne 2018).

Three architectures share one interface (:class:`Completer`): given the first
key ``y0 (B, 6)`` and, for frames ``1 .. T-1``, the surrounding keys and the
relative time (:func:`keyfill.learn.arnn.features.conditioning`), they predict
frames ``1 .. T-1`` one after the other, each from the previous prediction.

* :class:`ARNN` (section 6, Figure 6): ``Y'_{t-1}``, ``X_K`` and ``X_{K+1}``
  each pass through their own two-layer linear pose-feature extractor; the
  features and ``t_rel`` are concatenated and go through two GRU layers of 100
  units, then a feed-forward part of two linear layers of 10 units and a
  linear map to a 6-D residual that is added to ``Y'_{t-1}``. SELU between
  stages. Dropout (section 7.3) after the first and second GRU layers with
  drop probabilities 0.1 and 0.05 and after the two feed-forward layers with
  0.2 and 0.1: the paper's "probabilities 0.9 and 0.95 ... 0.8 and 0.9" are
  TensorFlow keep probabilities.
* :class:`NoMemory` (section 9): the same inputs and feed-forward part, with
  the GRU layers replaced by linear layers; no hidden state.
* :class:`Segregated` (section 9, Figure 14): a motion-pattern RNN that sees
  only ``Y'_{t-1}`` predicts a frame, and a feed-forward interpolation network
  conditioned on the keys, ``t_rel`` and that prediction adds a correction.

Layer widths of the two comparison networks are chosen so that all three have
about the same number of weights (the paper adjusts them "to produce a fair
comparison"). In training, a batch is either teacher-forced (the previous
*true* frame is the input, so the GRUs run fused over whole sequences) or
free-running (the network's own predictions, one step at a time), as chosen by
the scheduled-sampling curriculum (:mod:`keyfill.learn.arnn.task`).

Trained models are loaded and used by :mod:`keyfill.learn.arnn.model`.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from keyfill.errors import UsageError
from keyfill.learn.arnn.features import conditioning
from keyfill.learn.lamp_data import NUM_VARIABLES

ARCHITECTURES = ("arnn", "no-memory", "segregated")
#: drop probabilities after GRU layer 1, GRU layer 2, feed-forward layer 1, feed-forward layer 2
DROPOUT = (0.1, 0.05, 0.2, 0.1)


def _drop(x: torch.Tensor, p: float, training: bool, generator: torch.Generator | None) -> torch.Tensor:
    """Inverted dropout with an explicit generator (so training is reproducible without global seeding)."""
    if not training or p == 0.0:
        return x
    keep = torch.rand(x.shape, generator=generator, dtype=x.dtype) >= p
    return x * keep / (1.0 - p)


def _gru_step(gru: nn.GRU, x: torch.Tensor, h: torch.Tensor | None) -> torch.Tensor:
    """One step ``(B, in) -> (B, hidden)`` of a one-layer ``nn.GRU`` (the computation of ``nn.GRUCell``).

    Calling the ``nn.GRU`` module on a length-1 sequence costs about twice as
    much per frame; the weights stay those of the fused layer used for
    teacher-forced batches.
    """
    if h is None:
        h = x.new_zeros(x.shape[0], gru.hidden_size)
    return torch._VF.gru_cell(x, h, gru.weight_ih_l0, gru.weight_hh_l0, gru.bias_ih_l0, gru.bias_hh_l0)


class PoseFeatures(nn.Module):
    """Two linear layers with a SELU between them: a 6-D pose -> ``size`` features."""

    def __init__(self, size: int, inputs: int = NUM_VARIABLES):
        super().__init__()
        self.first = nn.Linear(inputs, size)
        self.second = nn.Linear(size, size)

    def forward(self, pose: torch.Tensor) -> torch.Tensor:
        return self.second(torch.selu(self.first(pose)))


class FeedForward(nn.Module):
    """The feed-forward part: two SELU layers (dropout after each) and a linear map to a 6-D residual."""

    def __init__(self, inputs: int, width: int, dropout: tuple[float, float]):
        super().__init__()
        self.first = nn.Linear(inputs, width)
        self.second = nn.Linear(width, width)
        self.out = nn.Linear(width, NUM_VARIABLES)
        self.dropout = dropout

    def forward(self, x: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        x = _drop(torch.selu(self.first(x)), self.dropout[0], self.training, generator)
        x = _drop(torch.selu(self.second(x)), self.dropout[1], self.training, generator)
        return self.out(x)


class Completer(nn.Module):
    """Base of the three architectures.

    Subclasses implement :meth:`key_features` (all frames at once),
    :meth:`sequence` (teacher-forced, all frames at once) and :meth:`step`
    (one frame from the previous prediction and a recurrent state).
    """

    arch = ""

    def key_features(self, x_prev, x_next, t_rel) -> torch.Tensor:
        """``(B, T-1, C)`` features of the keys and relative times."""
        raise NotImplementedError

    def sequence(self, y_prev, cond, generator) -> torch.Tensor:
        """Teacher forcing: predictions ``(B, T-1, 6)`` from the true previous frames ``y_prev (B, T-1, 6)``."""
        raise NotImplementedError

    def step(self, y_prev, cond_t, state, generator):
        """One frame: ``(y_t (B, 6), state)`` from ``y_prev (B, 6)`` and ``cond_t (B, C)``."""
        raise NotImplementedError

    def forward(self, y0, x_prev, x_next, t_rel, teacher=None, generator=None) -> torch.Tensor:
        """Predict frames ``1 .. T-1``.

        Args:
            y0: ``(B, 6)`` the first key (frame 0).
            x_prev, x_next, t_rel: ``(B, T-1, 6)``, ``(B, T-1, 6)``, ``(B, T-1, 1)`` from
                :func:`~keyfill.learn.arnn.features.conditioning`.
            teacher: ``(B, T-1, 6)`` true frames ``0 .. T-2`` to feed instead of the
                predictions (teacher forcing), or None to run free.
            generator: random generator for dropout.

        Returns:
            ``(B, T-1, 6)`` predicted frames ``1 .. T-1``.
        """
        cond = self.key_features(x_prev, x_next, t_rel)
        if teacher is not None:
            return self.sequence(teacher, cond, generator)
        y, state, out = y0, None, []
        for cond_t in cond.unbind(dim=1):  # unbind, not cond[:, t]: one gradient buffer, not one per frame
            y, state = self.step(y, cond_t, state, generator)
            out.append(y)
        return torch.stack(out, dim=1)


class ARNN(Completer):
    """The autoregressive recurrent network of section 6."""

    arch = "arnn"

    def __init__(self, feature_size: int = 16, hidden_size: int = 100, ff_size: int = 10, dropout=DROPOUT):
        super().__init__()
        self.pose = PoseFeatures(feature_size)
        self.key_before = PoseFeatures(feature_size)
        self.key_after = PoseFeatures(feature_size)
        self.gru1 = nn.GRU(3 * feature_size + 1, hidden_size, batch_first=True)
        self.gru2 = nn.GRU(hidden_size, hidden_size, batch_first=True)
        self.ff = FeedForward(hidden_size, ff_size, dropout[2:])
        self.dropout = dropout

    def key_features(self, x_prev, x_next, t_rel):
        return torch.cat([self.key_before(x_prev), self.key_after(x_next), t_rel], dim=-1)

    def sequence(self, y_prev, cond, generator):
        x = torch.selu(torch.cat([self.pose(y_prev), cond], dim=-1))
        a = _drop(torch.selu(self.gru1(x)[0]), self.dropout[0], self.training, generator)
        b = _drop(torch.selu(self.gru2(a)[0]), self.dropout[1], self.training, generator)
        return y_prev + self.ff(b, generator)

    def step(self, y_prev, cond_t, state, generator):
        h1, h2 = (None, None) if state is None else state
        x = torch.selu(torch.cat([self.pose(y_prev), cond_t], dim=-1))
        h1 = _gru_step(self.gru1, x, h1)
        a = _drop(torch.selu(h1), self.dropout[0], self.training, generator)
        h2 = _gru_step(self.gru2, a, h2)
        b = _drop(torch.selu(h2), self.dropout[1], self.training, generator)
        return y_prev + self.ff(b, generator), (h1, h2)


class NoMemory(Completer):
    """Section 9's keyframe-conditioned feed-forward network: the ARNN with linear layers for GRUs."""

    arch = "no-memory"

    def __init__(self, feature_size: int = 16, hidden_size: int = 300, ff_size: int = 10, dropout=DROPOUT):
        super().__init__()
        self.pose = PoseFeatures(feature_size)
        self.key_before = PoseFeatures(feature_size)
        self.key_after = PoseFeatures(feature_size)
        self.layer1 = nn.Linear(3 * feature_size + 1, hidden_size)
        self.layer2 = nn.Linear(hidden_size, hidden_size)
        self.ff = FeedForward(hidden_size, ff_size, dropout[2:])
        self.dropout = dropout

    def key_features(self, x_prev, x_next, t_rel):
        return torch.cat([self.key_before(x_prev), self.key_after(x_next), t_rel], dim=-1)

    def sequence(self, y_prev, cond, generator):
        x = torch.selu(torch.cat([self.pose(y_prev), cond], dim=-1))
        a = _drop(torch.selu(self.layer1(x)), self.dropout[0], self.training, generator)
        b = _drop(torch.selu(self.layer2(a)), self.dropout[1], self.training, generator)
        return y_prev + self.ff(b, generator)

    def step(self, y_prev, cond_t, state, generator):
        return self.sequence(y_prev, cond_t, generator), None


class Segregated(Completer):
    """Section 9's segregated network: an unconditioned motion-pattern RNN plus a key-conditioned correction."""

    arch = "segregated"

    def __init__(self, feature_size: int = 16, hidden_size: int = 100, ff_size: int = 10, interp_size: int = 76,
                 dropout=DROPOUT):
        super().__init__()
        # motion-pattern network: sees only the previous frame
        self.pose = PoseFeatures(feature_size)
        self.gru1 = nn.GRU(feature_size, hidden_size, batch_first=True)
        self.gru2 = nn.GRU(hidden_size, hidden_size, batch_first=True)
        self.ff = FeedForward(hidden_size, ff_size, dropout[2:])
        # interpolation network: keys, t_rel and the motion network's frame -> correction
        self.predicted = PoseFeatures(feature_size)
        self.key_before = PoseFeatures(feature_size)
        self.key_after = PoseFeatures(feature_size)
        self.interp = FeedForward(3 * feature_size + 1, interp_size, dropout[2:])
        self.dropout = dropout

    def key_features(self, x_prev, x_next, t_rel):
        return torch.cat([self.key_before(x_prev), self.key_after(x_next), t_rel], dim=-1)

    def _correct(self, y_prev, b, cond, generator):
        """The motion network's frame from its GRU output ``b``, plus the interpolation network's correction."""
        y_rnn = y_prev + self.ff(_drop(torch.selu(b), self.dropout[1], self.training, generator), generator)
        x = torch.selu(torch.cat([self.predicted(y_rnn), cond], dim=-1))
        return y_rnn + self.interp(x, generator)

    def sequence(self, y_prev, cond, generator):
        a = _drop(torch.selu(self.gru1(torch.selu(self.pose(y_prev)))[0]), self.dropout[0], self.training, generator)
        return self._correct(y_prev, self.gru2(a)[0], cond, generator)

    def step(self, y_prev, cond_t, state, generator):
        h1, h2 = (None, None) if state is None else state
        h1 = _gru_step(self.gru1, torch.selu(self.pose(y_prev)), h1)
        h2 = _gru_step(self.gru2, _drop(torch.selu(h1), self.dropout[0], self.training, generator), h2)
        return self._correct(y_prev, h2, cond_t, generator), (h1, h2)


_CLASSES = {"arnn": ARNN, "no-memory": NoMemory, "segregated": Segregated}


def build(arch: str, generator: torch.Generator | None = None, **sizes) -> Completer:
    """A freshly initialised network of architecture ``arch`` (``"arnn"``, ``"no-memory"``, ``"segregated"``).

    Linear layers get LeCun-normal weights (the initialisation SELU networks
    assume) and zero biases; the residual output layers start 10x smaller so a
    new network nearly holds the previous frame; GRU weights are uniform in
    ``+-1/sqrt(hidden)`` (PyTorch's default). All draws use ``generator``.
    """
    if arch not in _CLASSES:
        raise UsageError(f"unknown architecture {arch!r}; choose one of {', '.join(ARCHITECTURES)}")
    net = _CLASSES[arch](**sizes)
    with torch.no_grad():
        for name, module in net.named_modules():
            if isinstance(module, nn.Linear):
                scale = 0.1 if name.endswith(".out") else 1.0
                nn.init.normal_(module.weight, 0.0, scale / math.sqrt(module.in_features), generator=generator)
                nn.init.zeros_(module.bias)
            elif isinstance(module, nn.GRU):
                bound = 1.0 / math.sqrt(module.hidden_size)
                for p in module.parameters():
                    nn.init.uniform_(p, -bound, bound, generator=generator)
    return net


def num_weights(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


def run(net: Completer, frames: torch.Tensor, is_key: torch.Tensor, teacher: bool = False, generator=None):
    """Predictions ``(B, T-1, 6)`` for frames ``1 .. T-1`` of a batch (keys ``is_key``; teacher forcing optional)."""
    x_prev, x_next, t_rel, _ = conditioning(frames, is_key)
    return net(frames[:, 0], x_prev, x_next, t_rel, teacher=frames[:, :-1] if teacher else None,
               generator=generator)


class StepGraph(nn.Module):
    """One step of a lamp network with a packed state ``(B, 2, H)``: what ``keyfill export`` writes."""

    def __init__(self, net: Completer):
        super().__init__()
        self.net = net.eval()

    def forward(self, y_prev, key_before, key_after, t_rel, state):
        cond = self.net.key_features(key_before, key_after, t_rel)
        if isinstance(self.net, NoMemory):
            y, _ = self.net.step(y_prev, cond, None, None)
            return y, state + 0.0
        y, (h1, h2) = self.net.step(y_prev, cond, (state[:, 0], state[:, 1]), None)
        return y, torch.stack([h1, h2], dim=1)


def state_size(net: Completer) -> int:
    """``H`` of the packed state ``(B, 2, H)`` of :class:`StepGraph` (1 for the memoryless network)."""
    return 1 if isinstance(net, NoMemory) else net.gru1.hidden_size
