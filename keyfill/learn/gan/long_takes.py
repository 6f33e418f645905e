"""Long takes: a key range of any length filled by overlapping windows (numpy; issue 44).

The generator is fully convolutional, but a model fills at most ``GanConfig.max_frames`` frames at
once (its ONNX graph is exported for that many). :func:`keyfill.learn.gan.model.complete_motion`
fills a longer key range window by window:

* :func:`windows`: each window runs from a key to a key over at most ``max_frames`` frames; the
  next one starts :data:`OVERLAP` frames (or the keys nearest to that) before the window's end, so
  two consecutive windows share frames, and no frame is in three.
* Each window is completed as a key range of its own: its keys re-centred, its own spline base or
  root path moved onto its key roots, whole keys made exact in the ranges. The windows share one
  Motion DNA and one draw of noise (:func:`take_noise`, a window takes the noise of its latent
  steps), so overlapping windows make nearly the same motion.
* :func:`fill_take` writes each window into the take's arrays; where two windows overlap the
  later one fades in (:func:`cross_fade`, smoothstep weights from the first shared key to the last;
  the driven joints blended in their ranges' angles, so they stay in range). At a shared key both
  windows already hold the key.

Why overlap rather than windows that share only their boundary key (as the transformer's spans
do): near its ends a window sees padding instead of the keys beyond, and its spline base ends
with one-sided tangents. Measured on the shipped ``bandai2-gan`` through its graph (8,000 frames
of a walk, keys every 60 frames, windows of 2,048 frames, against one window over the whole range;
largest over joints): sharing only a key, the joint acceleration at a seam reaches 21.7 cm/frame^2
(one window: 0.73) and the motion is up to 77 cm from the one window's; with the overlap of 636
frames, 0.81 (0.77) and at most 14 cm, mean 2.5 cm (the windows also see their keys at other
offsets of the generator's 64-frame grid). Overlaps of 120 and 318 frames gave 0.91 and 0.75,
18 and 16 cm. The overlap costs ``OVERLAP / max_frames`` more network time (8 % with 8,192-frame
windows). Time and memory are linear in frames: the windows' outputs are written into the take's
arrays, and one window's arrays are held at a time.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.learn.gan.config import EFFECTIVE_RECEPTIVE_FIELD
from keyfill.learn.gan.ranges import JointRanges, range_angles

#: the generator takes a multiple of this many frames (keyfill.learn.gan.network.GENERATOR_MULTIPLE; no torch here)
FRAME_MULTIPLE = 64
#: frames consecutive windows share where the keys allow (at most a quarter of a window): the effective
#: receptive field, so the middle of their cross-fade is half of it (a latent step's 318 frames) from
#: either window's end
OVERLAP = EFFECTIVE_RECEPTIVE_FIELD


def windows(key_frames, max_frames: int, overlap: int = OVERLAP) -> list[tuple[int, int]]:
    """The windows a key range is filled by: ``[(first, last)]``, indices into ``key_frames (K,)`` (increasing).

    A window runs from a key to a key over at most ``max_frames`` frames, as many keys as fit. The next one
    starts at the last key at least ``min(overlap, max_frames // 4)`` frames before the window's last key, but
    after its first and not before the previous window's last (no frame is in three windows); where the
    gaps leave no room two windows share only their boundary key. A range of at most ``max_frames`` frames
    is one window. Every gap must be shorter than ``max_frames``.
    """
    k = np.asarray(key_frames, dtype=np.int64)
    share = min(int(overlap), int(max_frames) // 4)
    out, first, before = [], 0, 0  # before: the previous window's last key
    while True:
        last = max(int(np.searchsorted(k, k[first] + max_frames - 1, side="right")) - 1, first)
        out.append((first, last))
        if last >= len(k) - 1:
            return out
        nxt = int(np.searchsorted(k, k[last] - share, side="right")) - 1
        first, before = min(max(nxt, first + 1, before), last), last


def latent_steps(frames: int) -> int:
    """The generator's latent steps for a key range of ``frames`` frames (padded to a multiple of 64)."""
    return -(-int(frames) // FRAME_MULTIPLE)


def take_noise(noise_dim: int, key_frames: np.ndarray, plan, seed: int) -> np.ndarray | None:
    """``(1, noise_dim, S)`` float32: a take's noise (None when ``noise_dim`` is 0), one draw from
    ``torch.Generator().manual_seed(seed)`` over the latent steps its windows ``plan`` (:func:`windows`)
    reach; window ``(i, j)`` takes ``S`` from ``(key_frames[i] - key_frames[0]) // 64``. A key range of one
    window so gets the noise :func:`keyfill.learn.gan.model.generate` draws from the seed."""
    if not noise_dim:
        return None
    import torch

    k0 = int(key_frames[0])
    steps = max((int(key_frames[i]) - k0) // FRAME_MULTIPLE + latent_steps(key_frames[j] - key_frames[i] + 1)
                for i, j in plan)
    return torch.randn(1, noise_dim, steps, generator=torch.Generator().manual_seed(int(seed))).numpy()


def check_anchors(coords: np.ndarray, key_frames: np.ndarray, plan, max_frames: int) -> None:
    """A :class:`UsageError` when a window of partial keys (``coords (K, J, 3)`` bool, the model's hierarchy)
    gives the root's position at no key: its root path would have no anchor."""
    for i, j in plan:
        if not coords[i : j + 1, 0].any():
            where = "" if len(plan) == 1 else (f", in every {max_frames} frames the gan model fills at once: keys "
                                                f"{int(key_frames[i])}-{int(key_frames[j])} give none")
            raise UsageError(f"partial keys must give the root's position at one key at least (the path has no "
                             f"anchor otherwise){where}")


def fill_take(quats: np.ndarray, root: np.ndarray, key_frames: np.ndarray, plan, ranges: JointRanges,
              fill: Callable[[int, int], tuple[np.ndarray, np.ndarray]]) -> None:
    """Write the windows ``plan`` of a take into ``quats (F, J, 4)`` and ``root (F, 3)`` (in place; frames from
    the first key to the last, the root joint and the driven ones), cross-fading where they overlap.

    ``fill(i, j)`` gives window ``(i, j)``'s ``(quats (T, J, 4), root (T, 3))`` for its ``T`` frames from
    ``key_frames[i]`` to ``key_frames[j]``; it may read ``quats`` and ``root`` only at no frame of the take.
    """
    driven = np.concatenate([[0], ranges.driven])
    done = int(key_frames[0]) - 1  # the last frame that holds the windows' output
    for i, j in plan:
        a, b = int(key_frames[i]), int(key_frames[j])
        wq, wroot = fill(i, j)
        if done > a:
            n = done - a + 1
            quats[a : done + 1], root[a : done + 1] = cross_fade(ranges, quats[a : done + 1], root[a : done + 1],
                                                                 wq[:n], wroot[:n])
        quats[done + 1 : b + 1, driven] = wq[done - a + 1 :, driven]
        root[done + 1 : b + 1] = wroot[done - a + 1 :]
        done = b


def cross_fade(ranges: JointRanges, quats: np.ndarray, root: np.ndarray, new_quats: np.ndarray,
               new_root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(quats (n, J, 4), root (n, 3))``: the frames two windows share, from the earlier window's ``quats``
    and ``root`` to the later one's, with smoothstep weights (0 on the first frame, 1 on the last).

    The root's position is lerped, its rotation nlerped (signs aligned); the driven joints are blended in
    their ranges' Euler angles (:func:`~keyfill.learn.gan.ranges.range_angles`), so they stay in the ranges;
    other joints are ``quats``'. Where both windows hold the same rotation (a shared key), so does the blend.
    """
    n = len(quats)
    u = np.arange(n) / max(n - 1, 1)
    w = 3 * u**2 - 2 * u**3
    out = np.array(quats, dtype=np.float64, copy=True)
    q0, q1 = quats[:, 0], new_quats[:, 0]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    out[:, 0] = R.quat_normalize((1 - w[:, None]) * q0 + w[:, None] * q1)
    ang = (1 - w[:, None, None]) * range_angles(ranges, quats) + w[:, None, None] * range_angles(ranges, new_quats)
    for d, j in enumerate(ranges.driven):
        out[:, j] = R.euler_to_quat(ang[:, d], ranges.orders[d])
    return out, (1 - w[:, None]) * root + w[:, None] * new_root
