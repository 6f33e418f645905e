"""Each joint's Euler order and feasible angle ranges, estimated from a corpus (section 3.3).

The paper lists hand-made ranges and orders for the CMU skeleton (its Table 6).
keyfill serves any skeleton, so it derives them from the training corpus with
this rule (all angles radians, in the joint's own local axes as the file
defines them, not the paper's bone-aligned axes):

1. *Which joints.* Joint 0 (the root) has no range: its rotation is the
   continuous 6D representation. A joint is *driven* when some descendant has
   a non-zero offset, so its rotation moves a joint position; only driven
   joints get Euler angles from the network. The others (leaves such as end
   joints) move nothing the losses can see; ``complete`` interpolates them
   between the keys.
2. *Order.* For each of the six intrinsic orders, the middle angle of every
   frame is computed; the order whose middle angle stays closest to zero (the
   smallest of ``max(|P_lo|, |P_hi|)``, the ``P`` percentiles of the middle
   angle) is chosen, so the narrowest range sits in the middle and gimbal lock
   (middle angle +-90 degrees) is as far away as the data allows. Ties (within
   1e-3 rad) keep the order of the file's channels.
3. *Ranges.* For each of the three angles, its circular mean ``c``; the
   angles' differences from ``c`` wrapped into (-pi, pi]; their percentiles
   ``P_lo = 0.5`` and ``P_hi = 99.5`` (robust to a few bad frames); a margin of
   ``10 %`` of that width plus ``5 degrees`` on each side. An angle whose
   percentile width is under 0.5 degrees is held constant (a range of zero
   width at its median: the network cannot move it). The middle angle's range
   is finally clipped to [-85, 85] degrees, the outer angles' widths to a full turn.

The result is plain arrays (:class:`JointRanges`), stored in a model's
``config.json``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill import rotations as R
from keyfill.errors import ModelError
from keyfill.motion import Skeleton

P_LO, P_HI = 0.5, 99.5  #: robust percentiles of each angle
MARGIN_FRACTION = 0.10  #: margin as a share of the percentile width
MARGIN = np.radians(5.0)  #: plus this, on each side
STATIC = np.radians(0.5)  #: angles moving less than this are held constant
MIDDLE_LIMIT = np.radians(85.0)  #: the middle angle never reaches gimbal lock
MAX_FRAMES = 100_000  #: frames sampled (evenly) from a corpus


@dataclass(frozen=True, eq=False)
class JointRanges:
    """Euler orders and ranges of the driven joints.

    Attributes:
        driven: ``(D,)`` int, the driven joints (ascending, never joint 0).
        orders: ``D`` intrinsic Euler orders (``"XZY"``, ...).
        lo, hi: ``(D, 3)`` float radians, the range of each angle in the order's sequence.
    """

    driven: np.ndarray
    orders: tuple[str, ...]
    lo: np.ndarray
    hi: np.ndarray

    def __post_init__(self):
        D = len(self.driven)
        if len(self.orders) != D or np.shape(self.lo) != (D, 3) or np.shape(self.hi) != (D, 3):
            raise ModelError("joint ranges: driven joints, orders and limits disagree")
        if np.any(np.asarray(self.hi) < np.asarray(self.lo)):
            raise ModelError("joint ranges: an upper limit is below its lower limit")

    def to_json(self) -> dict:
        return {"driven": [int(j) for j in self.driven], "orders": list(self.orders),
                "lo": np.asarray(self.lo).tolist(), "hi": np.asarray(self.hi).tolist()}

    @classmethod
    def from_json(cls, data: dict) -> JointRanges:
        """The ranges :meth:`to_json` wrote (``ValueError`` for limits that are not bounded numbers)."""
        from keyfill.learn.modelfile import bounded_array

        return cls(np.asarray(data["driven"], dtype=np.int64), tuple(R.check_order(o) for o in data["orders"]),
                   bounded_array(data["lo"], "the joint ranges' lower limits").reshape(-1, 3),
                   bounded_array(data["hi"], "the joint ranges' upper limits").reshape(-1, 3))


def driven_joints(skeleton: Skeleton, atol: float = 1e-9) -> np.ndarray:
    """``(D,)`` joints other than 0 whose rotation moves some descendant (a non-zero offset below them)."""
    par = skeleton.parents
    J = len(par)
    moves = np.zeros(J, dtype=bool)  # some descendant has a non-zero offset
    for j in range(J - 1, 0, -1):
        p = par[j]
        if p >= 0 and (moves[j] or np.linalg.norm(skeleton.offsets[j]) > atol):
            moves[p] = True
    return np.flatnonzero(moves[1:]) + 1


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def choose_order(quats: np.ndarray, preferred: str) -> str:
    """The order whose middle angle keeps closest to zero for ``quats (N, 4)`` (rule 2)."""
    orders = [preferred] + [o for o in R.EULER_ORDERS if o != preferred]
    best, best_score = preferred, np.inf
    for o in orders:
        mid = R.quat_to_euler(quats, o)[:, 1]
        score = max(abs(np.percentile(mid, P_LO)), abs(np.percentile(mid, P_HI)))
        if score < best_score - 1e-3:
            best, best_score = o, score
    return best


def angle_range(angles: np.ndarray, middle: bool) -> tuple[float, float]:
    """``(lo, hi)`` radians of one angle's samples ``(N,)`` (rule 3)."""
    c = float(np.arctan2(np.sin(angles).mean(), np.cos(angles).mean()))
    d = _wrap(angles - c)
    a, b = np.percentile(d, P_LO), np.percentile(d, P_HI)
    if b - a < STATIC:
        m = c + float(np.median(d))
        return m, m
    margin = MARGIN_FRACTION * (b - a) + MARGIN
    lo, hi = c + a - margin, c + b + margin
    if middle:
        return max(lo, -MIDDLE_LIMIT), min(hi, MIDDLE_LIMIT)
    if hi - lo > 2 * np.pi:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - np.pi, mid + np.pi
    return float(lo), float(hi)


def estimate_ranges(skeleton: Skeleton, quats: np.ndarray) -> JointRanges:
    """The :class:`JointRanges` of ``skeleton`` from local quaternions ``quats (N, J, 4)`` of a corpus."""
    quats = np.asarray(quats, dtype=np.float64)
    if len(quats) > MAX_FRAMES:
        quats = quats[np.linspace(0, len(quats) - 1, MAX_FRAMES).astype(np.int64)]
    driven = driven_joints(skeleton)
    file_orders = skeleton.euler_orders
    orders, lo, hi = [], [], []
    for j in driven:
        q = quats[:, j]
        o = choose_order(q, file_orders[j])
        ang = R.quat_to_euler(q, o)
        rng = [angle_range(ang[:, i], middle=(i == 1)) for i in range(3)]
        orders.append(o)
        lo.append([r[0] for r in rng])
        hi.append([r[1] for r in rng])
    return JointRanges(driven, tuple(orders), np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3))


def range_angles(ranges: JointRanges, quats: np.ndarray) -> np.ndarray:
    """``(..., D, 3)`` radians: the driven joints' rotations in ``quats (..., J, 4)`` as Euler angles in their
    orders, the middle angle in [-90, 90] degrees and the outer ones wrapped to the nearest turn of their
    range's centre (so an angle inside its range is the value RC-FK would give)."""
    out = []
    for d, j in enumerate(ranges.driven):
        ang = R.quat_to_euler(quats[..., j, :], ranges.orders[d])
        c = 0.5 * (ranges.lo[d] + ranges.hi[d])
        out.append(np.concatenate([c[[0]] + _wrap(ang[..., :1] - c[0]), ang[..., 1:2],
                                   c[[2]] + _wrap(ang[..., 2:] - c[2])], axis=-1))
    return np.stack(out, axis=-2)


def inside(ranges: JointRanges, quats: np.ndarray, tolerance: float = 1e-6) -> np.ndarray:
    """``(..., D)`` bool: whether each driven joint's rotation in ``quats (..., J, 4)`` lies in its ranges
    (:func:`range_angles`), to ``tolerance`` radians."""
    ang = range_angles(ranges, quats)
    return np.all((ang >= ranges.lo - tolerance) & (ang <= ranges.hi + tolerance), axis=-1)


def snap_in_range(ranges: JointRanges, quats: np.ndarray, key_frames: np.ndarray, key_quats: np.ndarray) -> np.ndarray:
    """``quats (T, J, 4)`` whose driven joints equal ``key_quats (K, J, 4)`` at ``key_frames``, inside the ranges.

    The exact-key correction of :func:`keyfill.learn.exact_keys.snap_to_keys` done in the ranges' Euler
    angles (:func:`range_angles`): each key's angle residual is spread over its neighbouring gaps with
    smoothstep weights, the result clipped to the ranges between keys, and the key frames set to the
    keys' angles. Generated angles inside their ranges stay inside (only a key that is itself outside
    its range is outside, at that key). Frames outside the key range get the first or last key's residual.
    Returns new quaternions; joints not driven are unchanged.
    """
    from keyfill.interpolate import segment_coordinates

    k = np.asarray(key_frames, dtype=np.int64)
    ang = range_angles(ranges, quats)  # (T, D, 3)
    key_ang = range_angles(ranges, key_quats)  # (K, D, 3)
    res = key_ang - ang[k]
    s, u = segment_coordinates(len(quats), k)
    w = (3 * u**2 - 2 * u**3)[:, None, None]
    fixed = np.clip(ang + (1 - w) * res[s] + w * res[s + 1], ranges.lo, ranges.hi)
    fixed[k] = key_ang
    out = np.array(quats, dtype=np.float64, copy=True)
    for d, j in enumerate(ranges.driven):
        out[:, j] = R.euler_to_quat(fixed[:, d], ranges.orders[d])
    return out
