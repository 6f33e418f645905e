"""Bezier animation curves, a core data type: one curve per control, all keyed at the same times.

A *control* is one animated channel of the skeleton: a translation channel
(``"Xposition"``, file units) or a rotation channel (``"Zrotation"``, radians,
one Euler angle in the joint's declared intrinsic order). Every control is a
piecewise cubic Bezier curve in the (time, value) plane with knots at the key
times ``t_0 < ... < t_{K-1}`` (frames). On the segment from key ``k`` to
``k+1`` the four control points are::

    P0 = (t_k,                      v_k)
    P1 = (t_k + out[k].width,       v_k + out[k].height)
    P2 = (t_k+1 - in[k+1].width,    v_k+1 - in[k+1].height)
    P3 = (t_k+1,                    v_k+1)

so a tangent is the 2-vector ``theta = (X, Y)`` of Ciccone et al. 2019: ``X``
(width, frames) sets the timing, ``Y`` (height, value units) the shape; the
curve's slope at the key is ``Y / X``. These are the same numbers as the
``pxr.Ts`` knot's tangent width and ``width * slope`` (see
:mod:`keyfill.io.usd_curves`). A key's tangents are *unified* when the in and
out tangents have the same slope (a C1 curve) and *broken* otherwise.

Evaluation is exact: for each time the cubic ``B^X(lambda) = t`` is solved for
``lambda`` in [0, 1] (safeguarded Newton, to machine precision), then
``c(t) = B^Y(lambda)``. Before the first key and after the last the curves
hold the end values. Widths must lie in ``[0, segment length]`` on both sides
of a segment (Eq. 7 of the paper), which keeps time increasing along each
segment (the curve is a function of time).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError, UsageError
from keyfill.motion import POSITION_CHANNELS, ROTATION_CHANNELS, Keys, Motion, Skeleton

_AXIS = {"X": 0, "Y": 1, "Z": 2}


class Control(NamedTuple):
    """One animated channel: ``joint`` index and BVH ``channel`` name."""

    joint: int
    channel: str

    @property
    def is_rotation(self) -> bool:
        return self.channel in ROTATION_CHANNELS

    @property
    def axis(self) -> int:
        """0, 1 or 2 for X, Y, Z."""
        return _AXIS[self.channel[0]]

    def name(self, skeleton: Skeleton) -> str:
        """``"Hips.Zrotation"``: how edit files and messages name the control."""
        return f"{skeleton.names[self.joint]}.{self.channel}"


@dataclass(frozen=True, eq=False)
class Curves:
    """Per-control Bezier curves with shared key times.

    Attributes:
        skeleton: the :class:`~keyfill.motion.Skeleton` the controls animate.
        fps: frames per second.
        num_frames: frames ``0 .. num_frames-1`` that :meth:`bake` produces.
        controls: ``C`` controls; joints' channels that are not controls keep
            their rest value (translation = the rest offset, angle = 0).
        times: ``(K,)`` key times in frames, strictly increasing, ``K >= 2``.
        values: ``(K, C)`` key values (radians for rotations, file units for translations).
        in_tan: ``(K, C, 2)`` incoming tangents ``(width, height)``.
        out_tan: ``(K, C, 2)`` outgoing tangents ``(width, height)``.
        broken: ``(K, C)`` bool, the key's two tangents may differ in slope.
    """

    skeleton: Skeleton
    fps: float
    num_frames: int
    controls: tuple[Control, ...]
    times: np.ndarray
    values: np.ndarray
    in_tan: np.ndarray
    out_tan: np.ndarray
    broken: np.ndarray

    def __post_init__(self):
        controls = tuple(Control(int(j), str(c)) for j, c in self.controls)
        times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        K, C = len(times), len(controls)
        values = np.asarray(self.values, dtype=np.float64)
        in_tan = np.asarray(self.in_tan, dtype=np.float64)
        out_tan = np.asarray(self.out_tan, dtype=np.float64)
        broken = np.asarray(self.broken, dtype=bool)
        if K < 2:
            raise DataError(f"curves need at least 2 keys, got {K}")
        if values.shape != (K, C) or in_tan.shape != (K, C, 2) or out_tan.shape != (K, C, 2) or broken.shape != (K, C):
            raise DataError(
                f"curve arrays disagree: {K} keys, {C} controls, values {values.shape}, "
                f"tangents {in_tan.shape} / {out_tan.shape}, broken {broken.shape}"
            )
        if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
            raise DataError("key times must be finite and strictly increasing")
        for a in (values, in_tan, out_tan):
            if not np.all(np.isfinite(a)):
                raise DataError("a key value or tangent is not finite")
        seg = np.diff(times)[:, None]
        tol = 1e-9 * max(1.0, float(times[-1] - times[0]))
        bad = (out_tan[:-1, :, 0] < -tol) | (out_tan[:-1, :, 0] > seg + tol)
        bad |= (in_tan[1:, :, 0] < -tol) | (in_tan[1:, :, 0] > seg + tol)
        if np.any(bad):
            k, c = np.argwhere(bad)[0]
            raise DataError(
                f"control {controls[c].name(self.skeleton)}: a tangent width between keys at "
                f"{times[k]:g} and {times[k + 1]:g} is negative or longer than the segment, "
                "so the curve would run backwards in time"
            )
        seen = set()
        for ctl in controls:
            if not 0 <= ctl.joint < self.skeleton.num_joints:
                raise DataError(
                    f"control on joint index {ctl.joint}: the skeleton has {self.skeleton.num_joints} joints"
                )
            if ctl.channel not in POSITION_CHANNELS + ROTATION_CHANNELS:
                raise DataError(f"unknown channel {ctl.channel!r}")
            if ctl in seen:
                raise DataError(f"control {ctl.name(self.skeleton)} appears twice")
            seen.add(ctl)
        if int(self.num_frames) < 1 or not (np.isfinite(self.fps) and self.fps > 0):
            raise DataError(f"curves need at least one frame and a positive fps (got {self.num_frames}, {self.fps})")
        for name, a in (
            ("times", times),
            ("values", values),
            ("in_tan", in_tan),
            ("out_tan", out_tan),
            ("broken", broken),
        ):
            a = a.copy()
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "controls", controls)
        object.__setattr__(self, "fps", float(self.fps))
        object.__setattr__(self, "num_frames", int(self.num_frames))

    # --- basic facts -------------------------------------------------------

    @property
    def num_keys(self) -> int:
        return len(self.times)

    @property
    def num_controls(self) -> int:
        return len(self.controls)

    def replace(self, **changes) -> Curves:
        return dataclasses.replace(self, **changes)

    def control_index(self, name: str) -> int:
        """Index of control ``"Joint.Channel"``; the error lists the controls of that joint."""
        joint, _, channel = name.rpartition(".")
        j = self.skeleton.index(joint) if joint else -1
        for i, c in enumerate(self.controls):
            if c.joint == j and c.channel.lower() == channel.lower():
                return i
        have = [c.channel for c in self.controls if c.joint == j]
        raise UsageError(
            f"unknown control {name!r}; "
            + (f"{joint} has {', '.join(have)}" if have else f"joint {joint!r} has no animated channels")
        )

    def key_index(self, time: float) -> int | None:
        """Index of the key at ``time`` (within 1e-9 frames), else None."""
        k = int(np.argmin(np.abs(self.times - time)))
        return k if abs(self.times[k] - time) <= 1e-9 else None

    def arrays(self) -> CurveArrays:
        """The key arrays, as :func:`evaluate_segments` takes them."""
        return CurveArrays(self.times, self.values, self.in_tan, self.out_tan)

    def segment(self, time) -> np.ndarray:
        """Segment index (keys ``s``, ``s+1``) of each time, clipped to ``[0, K-2]``."""
        return np.clip(np.searchsorted(self.times, time, side="right") - 1, 0, self.num_keys - 2)

    # --- evaluation --------------------------------------------------------

    def evaluate(self, time, controls=None) -> np.ndarray:
        """Values ``(T, n)`` of ``controls`` (indices; all by default) at times ``(T,)`` (frames)."""
        time = np.atleast_1d(np.asarray(time, dtype=np.float64))
        cols = np.arange(self.num_controls) if controls is None else np.asarray(controls, dtype=np.int64)
        return evaluate_segments(self.arrays(), time, self.segment(time), cols).value

    def derivative(self, time, controls=None) -> np.ndarray:
        """Time derivatives ``(T, n)`` (value units per frame); zero outside the keys."""
        time = np.atleast_1d(np.asarray(time, dtype=np.float64))
        cols = np.arange(self.num_controls) if controls is None else np.asarray(controls, dtype=np.int64)
        return evaluate_segments(self.arrays(), time, self.segment(time), cols).slope

    def bake(self, frames=None) -> Motion:
        """A :class:`Motion` sampled at ``frames`` (default ``0 .. num_frames-1``).

        Keys are attached when every key time is a whole frame inside the range.
        """
        sk = self.skeleton
        frames = np.arange(self.num_frames) if frames is None else np.asarray(frames, dtype=np.float64)
        rot, pos = controls_to_pose(sk, self.controls, self.evaluate(frames))
        keys = None
        whole = np.round(self.times)
        every_frame = np.array_equal(frames, np.arange(len(frames)))
        if every_frame and np.allclose(self.times, whole, atol=1e-9) and whole[0] >= 0 and whole[-1] < len(frames):
            keys = Keys(whole.astype(np.int64))
        return Motion(sk, self.fps, rot, pos, keys=keys)


def controls_to_pose(skeleton: Skeleton, controls, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local ``(rotations (T, J, 4), positions (T, J, 3))`` from control values ``(T, C)``.

    Rotation controls are Euler angles in each joint's order
    (:attr:`Skeleton.euler_orders`); missing angles are zero; translations
    default to the rest offsets.
    """
    T = values.shape[0]
    J = skeleton.num_joints
    angles = np.zeros((T, J, 3))
    pos = np.broadcast_to(skeleton.offsets, (T, J, 3)).copy()
    orders = skeleton.euler_orders
    for i, c in enumerate(controls):
        if c.is_rotation:
            angles[:, c.joint, orders[c.joint].index(c.channel[0])] = values[:, i]
        else:
            pos[:, c.joint, c.axis] = values[:, i]
    rot = np.empty((T, J, 4))
    for order in sorted(set(orders)):
        js = [j for j in range(J) if orders[j] == order]
        rot[:, js] = R.euler_to_quat(angles[:, js], order)
    return rot, pos


# --- segment maths -----------------------------------------------------------


class CurveArrays(NamedTuple):
    """Key ``times (K,)``, ``values (K, C)``, ``in_tan``, ``out_tan (K, C, 2)`` of :class:`Curves`
    (or the solver's working copies of them)."""

    times: np.ndarray
    values: np.ndarray
    in_tan: np.ndarray
    out_tan: np.ndarray


class SegmentEval:
    """Curve quantities at times ``(T,)`` for controls ``cols (n,)``, each ``(T, n)``.

    ``value``: c(t); ``lam``: the Bezier parameter; ``b1``, ``b2``: the
    Bernstein weights ``3 l (1-l)^2`` and ``3 l^2 (1-l)`` of the inner control
    points (the derivatives of ``c`` with respect to the out height at the
    segment start and minus the in height at its end); ``slope``: dc/dt,
    computed on first use (zero where the curves hold outside their keys).
    """

    def __init__(self, value, lam, b1, b2, parts):
        self.value, self.lam, self.b1, self.b2 = value, lam, b1, b2
        self._parts = parts
        self._slope = None

    def columns(self, idx) -> SegmentEval:
        """The same quantities for a subset ``idx`` of the columns."""
        a, b, dt, y0, dy1, y3, dy3, outside = self._parts
        parts = (
            a[:, idx],
            b[:, idx],
            dt,
            y0[:, idx],
            dy1[:, idx],
            y3[:, idx],
            dy3[:, idx],
            None if outside is None else outside[:, idx],
        )
        out = SegmentEval(self.value[:, idx], self.lam[:, idx], self.b1[:, idx], self.b2[:, idx], parts)
        if self._slope is not None:
            out._slope = self._slope[:, idx]
        return out

    @property
    def slope(self) -> np.ndarray:
        if self._slope is None:
            lam, one = self.lam, 1.0 - self.lam
            a, b, dt, y0, dy1, y3, dy3, outside = self._parts
            # d/dlambda of the Bezier in value and in time
            dy = 3.0 * (one * one * dy1 + 2.0 * lam * one * (y3 - dy3 - y0 - dy1) + lam * lam * dy3)
            dx = 3.0 * (one * one * a + 2.0 * lam * one * (b - a) + lam * lam * (1.0 - b)) * dt
            slope = dy / np.where(dx > 1e-300, dx, np.inf)
            self._slope = np.where(outside, 0.0, slope) if outside is not None else slope
        return self._slope


def evaluate_segments(curves: CurveArrays, time: np.ndarray, seg: np.ndarray, cols: np.ndarray) -> SegmentEval:
    """Evaluate controls ``cols (n,)`` at ``time (T,)`` on segments ``seg (T,)``.

    Times before the segment's first key or after its last give the end
    values with zero slope (the hold of the curves' ends).
    """
    t0 = curves.times[seg][:, None]
    dt = curves.times[seg + 1][:, None] - t0
    rel = time[:, None] - t0
    u = np.clip(rel / dt, 0.0, 1.0)
    k0, k1, c = seg[:, None], seg[:, None] + 1, cols[None, :]
    out = curves.out_tan[k0, c]  # (T, n, 2)
    inn = curves.in_tan[k1, c]
    a = out[..., 0] / dt  # normalised inner control point times
    b = 1.0 - inn[..., 0] / dt
    lam = solve_bezier_time(np.broadcast_to(u, a.shape), a, b)
    one = 1.0 - lam
    b1 = 3.0 * lam * one * one
    b2 = 3.0 * lam * lam * one
    y0 = curves.values[k0, c]
    y3 = curves.values[k1, c]
    dy1 = out[..., 1]  # y1 - y0
    dy3 = inn[..., 1]  # y3 - y2
    value = (one * one * one + b1) * y0 + b1 * dy1 + b2 * (y3 - dy3) + lam * lam * lam * y3
    outside = (rel < 0) | (rel > dt)
    return SegmentEval(value, lam, b1, b2, (a, b, dt, y0, dy1, y3, dy3, outside if outside.any() else None))


def solve_bezier_time(u: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``x(l) = u`` for ``l`` in [0, 1], where ``x`` is the Bezier (0, a, b, 1).

    ``x(l) = 3 a l (1-l)^2 + 3 b l^2 (1-l) + l^3`` with ``a, 1-b`` in [0, 1]
    is non-decreasing, so the root is unique. Newton's method from ``l = u``
    (exact at once for linear timing, ``a = 1/3``, ``b = 2/3``) converges in
    a few steps; entries where it would leave [0, 1] or stall (a flat spot of
    ``x``) finish by bisection. The result is exact to machine precision.
    """
    c1 = 3.0 * a
    c2 = 3.0 * b - 6.0 * a
    c3 = 1.0 + 3.0 * a - 3.0 * b
    lam = np.array(u, dtype=np.float64)
    for _ in range(8):
        f = ((c3 * lam + c2) * lam + c1) * lam - u
        df = (3.0 * c3 * lam + 2.0 * c2) * lam + c1
        step = f / np.where(df > 1e-12, df, np.inf)
        lam -= step
        if np.abs(step).max() <= 1e-15:
            if lam.min() >= 0.0 and lam.max() <= 1.0:
                return lam
            break
    f = ((c3 * lam + c2) * lam + c1) * lam - u
    bad = ~((lam >= 0) & (lam <= 1) & (np.abs(f) <= 1e-14))
    if bad.any():
        lam[bad] = _bisect(u[bad], c1[bad], c2[bad], c3[bad])
    return lam


def _bisect(u, c1, c2, c3) -> np.ndarray:
    """Root of the non-decreasing cubic ``c3 l^3 + c2 l^2 + c1 l = u`` in [0, 1] by bisection."""
    lo, hi = np.zeros_like(u), np.ones_like(u)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = ((c3 * mid + c2) * mid + c1) * mid < u
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)
