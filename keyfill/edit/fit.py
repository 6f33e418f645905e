"""Fit Bezier curves to a dense motion: values exact at the keys, tangents least-squares.

``fit(motion, keys)`` turns any :class:`~keyfill.motion.Motion` (a BVH
capture, a learned completion) into editable :class:`~keyfill.curves.Curves`:

* controls: every rotation channel of the skeleton (Euler angles in each
  joint's order, made continuous over time) and the translation channels of
  root joints and of joints whose translation moves away from the rest
  offset by more than 1e-6 of the skeleton's size in some frame (smaller
  wobbles, the float noise of exporters, are dropped: those joints bake to
  their rest offset); ``all_channels=True`` makes every channel a control;
* key values: the motion's values at the key frames, exactly;
* tangents: unified (one slope per key and control, so the curves are C1)
  with widths of a third of each segment (uniform timing), and slopes that
  minimise the squared error to every frame between the keys. A tiny pull
  toward Catmull-Rom slopes settles keys that no frame constrains.

Frames before the first key and after the last hold the end keys.
"""

from __future__ import annotations

import numpy as np

from keyfill.curves import Control, Curves
from keyfill.motion import POSITION_CHANNELS, ROTATION_CHANNELS, Keys, Motion

#: weight of the Catmull-Rom prior relative to one frame's squared error
_PRIOR = 1e-10


def controls_of(motion: Motion, all_channels: bool = False) -> tuple[Control, ...]:
    """The controls :func:`fit` makes for ``motion`` (see the module docstring)."""
    sk = motion.skeleton
    scale = max(1.0, float(np.abs(sk.offsets).max()))
    moved = np.abs(motion.positions - sk.offsets).max(axis=0) > 1e-6 * scale  # (J, 3)
    out = []
    for j, chans in enumerate(sk.channels):
        for c in chans:
            if (
                c in ROTATION_CHANNELS
                or c in POSITION_CHANNELS
                and (all_channels or sk.parents[j] < 0 or moved[j].any())
            ):
                out.append(Control(j, c))
    return tuple(out)


def control_values(motion: Motion, controls) -> np.ndarray:
    """Dense control values ``(F, C)``: continuous Euler angles (radians) and translations."""
    sk = motion.skeleton
    orders = sk.euler_orders
    F = motion.num_frames
    angles = motion.euler_angles()
    out = np.empty((F, len(controls)))
    for i, c in enumerate(controls):
        if c.is_rotation:
            out[:, i] = angles[:, c.joint, orders[c.joint].index(c.channel[0])]
        else:
            out[:, i] = motion.positions[:, c.joint, c.axis]
    return out


def fit(motion: Motion, keys: Keys, all_channels: bool = False) -> Curves:
    """Bezier curves through ``motion`` at ``keys`` (see the module docstring).

    Args:
        motion: the dense motion.
        keys: at least two key frames inside the motion.
        all_channels: make every channel of the skeleton a control, even static ones.

    Returns:
        :class:`Curves` whose baked frames equal ``motion`` at the keys (to
        rounding) and approximate it in between.
    """
    keys.check(motion.num_frames, min_keys=2)
    controls = controls_of(motion, all_channels)
    dense = control_values(motion, controls)  # (F, C)
    kf = keys.frames
    t = kf.astype(np.float64)
    K, C = len(kf), len(controls)
    values = dense[kf]
    h = np.diff(t)  # (K-1,)
    slopes = _fit_slopes(dense, kf, values, h)  # (K, C)

    in_tan = np.zeros((K, C, 2))
    out_tan = np.zeros((K, C, 2))
    w_in = np.concatenate([h[:1], h]) / 3.0  # width of the in side (first key: mirror)
    w_out = np.concatenate([h, h[-1:]]) / 3.0
    in_tan[..., 0] = w_in[:, None]
    in_tan[..., 1] = slopes * w_in[:, None]
    out_tan[..., 0] = w_out[:, None]
    out_tan[..., 1] = slopes * w_out[:, None]
    return Curves(
        skeleton=motion.skeleton,
        fps=motion.fps,
        num_frames=motion.num_frames,
        controls=controls,
        times=t,
        values=values,
        in_tan=in_tan,
        out_tan=out_tan,
        broken=np.zeros((K, C), dtype=bool),
    )


def _fit_slopes(dense: np.ndarray, kf: np.ndarray, values: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Least-squares key slopes ``(K, C)`` for uniform-timing cubic segments.

    With widths ``h/3`` on both sides, the segment from key ``k`` to ``k+1``
    at ``u = (f - t_k) / h_k`` is the Hermite cubic
    ``v_k H00 + v_k+1 H01 + h_k (m_k H10 + m_k+1 H11)``: linear in the slopes.
    """
    K = len(values)
    rows, targets = [], []
    for k in range(K - 1):
        f = np.arange(kf[k] + 1, kf[k + 1])
        if len(f) == 0:
            continue
        u = (f - kf[k]) / h[k]
        h00 = 2 * u**3 - 3 * u**2 + 1
        h01 = 3 * u**2 - 2 * u**3
        h10 = u**3 - 2 * u**2 + u
        h11 = u**3 - u**2
        a = np.zeros((len(f), K))
        a[:, k] = h[k] * h10
        a[:, k + 1] = h[k] * h11
        rows.append(a)
        targets.append(dense[f] - np.outer(h00, values[k]) - np.outer(h01, values[k + 1]))
    prior = _catmull_rom(values, h)
    reg = np.sqrt(_PRIOR) * np.eye(K)
    A = np.concatenate(rows + [reg]) if rows else reg
    B = np.concatenate(targets + [np.sqrt(_PRIOR) * prior]) if targets else np.sqrt(_PRIOR) * prior
    return np.linalg.lstsq(A, B, rcond=None)[0]


def _catmull_rom(values: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Key slopes ``(K, C)`` from neighbouring secants weighted for uneven spacing."""
    sec = np.diff(values, axis=0) / h[:, None]
    out = np.empty_like(values)
    out[0], out[-1] = sec[0], sec[-1]
    if len(values) > 2:
        hl, hr = h[:-1, None], h[1:, None]
        out[1:-1] = (hr * sec[:-1] + hl * sec[1:]) / (hl + hr)
    return out
