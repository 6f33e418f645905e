"""The transformer's architecture settings (:class:`ModelConfig`): what a model folder's ``architecture`` holds.

No torch: reading a model's settings (``keyfill info``, the ONNX runtime) needs none.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from keyfill import interpolate
from keyfill.errors import ModelError
from keyfill.learn.windows import axis_vector
from keyfill.limits import check_number

#: the pre-fills a model can be trained with (:attr:`ModelConfig.prefill`), by the names a model folder records
PREFILL_FUNCTIONS = {"interpolation": interpolate.linear_windows, "cubic": interpolate.cubic_windows,
                     "velocity": interpolate.velocity_windows}
PREFILLS = tuple(PREFILL_FUNCTIONS)
#: architecture settings added after the first models were written, with the value that behaves as before: at
#: that value they are left out of a model's ``config.json`` and of what ``--resume`` compares, so older runs
#: resume and retrain to the same bytes (:meth:`ModelConfig.recorded`)
LATER_ARCHITECTURE = {"prefill": "interpolation", "rotation_weight": 1.0, "key_distances": False,
                      "output_smoothing": 0, "foot_weight": 0.0, "smooth_weight": 0.0, "unknown_input": "prefill",
                      "velocity_input": False}
#: what the network reads in the frames it fills (:attr:`ModelConfig.unknown_input`)
UNKNOWN_INPUTS = ("prefill", "zero")
#: the highest order of :attr:`ModelConfig.output_smoothing` (a 65-tap kernel: more than a window)
MAX_SMOOTHING = 64
#: each number of a :class:`ModelConfig`: (whole number?, lowest, highest); larger sizes would exhaust memory
NUMBER_LIMITS = {"layers": (True, 1, 256), "d_model": (True, 1, 16384), "heads": (True, 1, 256),
                 "ffn": (True, 1, 65536), "max_frames": (True, 1, 100_000), "dropout": (False, 0, 0.99),
                 "kinematics_weight": (False, 0, 1e6), "fk_weight": (False, 0, 1e6), "rotation_weight": (False, 0, 1e6),
                 "foot_weight": (False, 0, 1e6), "smooth_weight": (False, 0, 1e6)}


@dataclass(frozen=True)
class ModelConfig:
    """Architecture and representation of a :class:`MotionTransformer`.

    Attributes:
        coordinates: ``"global"`` or ``"local"`` features and prediction.
        layers, d_model, heads, ffn, dropout: the BERT encoder.
        max_frames: length of the learnable position embedding (longest window).
        residual: add the network's output to the pre-filled input.
        kinematics_weight: weight of the IK loss (global) or FK loss (local), Eq. 15.
        rotation_weight: weight of the quaternion L1 loss (1: the paper's Eq. 15).
        fk_weight: global coordinates only: weight of an FK loss on the decoded
            output (positions by forward kinematics of the predicted rotations and
            the standard offsets, the positions the benchmark scores); 0 is the paper.
        facing_axis: the root's local forward axis, for the canonical frame.
        prefill: how unknown frames are filled before the network corrects them:
            ``"interpolation"`` (LERP/SLERP, the paper), ``"cubic"`` (C1 spline through the keys) or
            ``"velocity"`` (the interpolation plus the fading velocity of the given frames beside a gap).
        key_distances: add learnable embeddings of each frame's distance in frames to the previous and
            the next key (the "time to arrival" of Harvey et al. 2020), so the network reads a gap's length
            and its place in it directly. They start at zero: a model fine-tuned with them from one
            without starts as that model.
        foot_weight: weight of a foot-sliding term (issue 30): the mean squared horizontal speed, (m/s)^2,
            of the foot and toe joints of the decoded output (the positions a user gets) over the frame
            pairs the real window has in contact (:func:`keyfill.characters.feet.contacts` labels;
            :func:`keyfill.learn.realism_terms.foot_sliding_loss`). 0: off, as every shipped model.
        smooth_weight: weight of a smoothness term (issue 30): the mean excess of the decoded output's jerk
            (third difference of world joint positions, m/s^3) over the real window's at the same joint and
            frame, clipped at 0 (:func:`keyfill.learn.realism_terms.excess_jerk_loss`). 0: off.
        unknown_input: what the network reads in the frames that are not keys (issue 46): ``"prefill"`` (the
            pre-filled frames, as the paper) or ``"zero"`` (zeros, plus a mask channel that is 1 on keys and 0
            elsewhere: the Delta-Interpolator's layout). Either way a ``residual`` output is added to the
            pre-fill, so the network writes a correction of the interpolation it cannot see.
        velocity_input: the network also reads each frame's feature velocity: its features minus the previous
            frame's (0 on the first frame; with ``unknown_input`` ``"zero"``, 0 unless both frames are keys).
    """

    coordinates: str = "global"
    layers: int = 8
    d_model: int = 256
    heads: int = 8
    ffn: int = 512
    dropout: float = 0.1
    max_frames: int = 65
    residual: bool = True
    kinematics_weight: float = 0.01
    fk_weight: float = 0.0
    facing_axis: str = "+Y"
    prefill: str = "interpolation"
    rotation_weight: float = 1.0
    key_distances: bool = False
    output_smoothing: int = 0
    foot_weight: float = 0.0
    smooth_weight: float = 0.0
    unknown_input: str = "prefill"
    velocity_input: bool = False

    def __post_init__(self):
        for name, (whole, low, high) in NUMBER_LIMITS.items():  # before any arithmetic (heads 0, layers 1e9)
            check_number(name, getattr(self, name), low, high, whole=whole, error=ModelError)
        if self.coordinates not in ("global", "local"):
            raise ModelError(f"coordinates must be 'global' or 'local', not {self.coordinates!r}")
        if self.d_model % self.heads:
            raise ModelError(f"d_model {self.d_model} is not a multiple of heads {self.heads}")
        axis_vector(self.facing_axis)
        if self.prefill not in PREFILLS:
            raise ModelError(f"prefill must be one of {', '.join(PREFILLS)}, not {self.prefill!r}")
        if self.unknown_input not in UNKNOWN_INPUTS:
            raise ModelError(f"unknown_input must be one of {', '.join(UNKNOWN_INPUTS)}, not {self.unknown_input!r}")
        for name in ("residual", "key_distances", "velocity_input"):
            if not isinstance(getattr(self, name), bool):
                raise ModelError(f"{name} must be true or false, not {getattr(self, name)!r}")
        s = self.output_smoothing
        if type(s) is not int or not 0 <= s <= MAX_SMOOTHING or s % 2:
            raise ModelError(f"output_smoothing must be an even order from 0 to {MAX_SMOOTHING}, not {s!r}")

    def recorded(self) -> dict:
        """The settings a model file and a checkpoint record: all but later ones at their old value."""
        return {k: v for k, v in dataclasses.asdict(self).items() if LATER_ARCHITECTURE.get(k, ...) != v}

    def fill(self, quats: np.ndarray, root: np.ndarray, keys) -> tuple[np.ndarray, np.ndarray]:
        """Windows ``quats (B, T, J, 4)``, ``root (B, T, 3)`` pre-filled between ``keys`` (only keys are read)."""
        return PREFILL_FUNCTIONS[self.prefill](None, quats, root, keys)
