"""The in-betweening baselines that need no learning: ``linear``, ``cubic``, ``velocity``, ``zero-velocity``.

Each fills every frame from the key frames alone; frames at keys are copied from
the input unchanged (bit-identical), frames before the first key or after the
last hold that key. Each comes twice, on one :class:`~keyfill.motion.Motion`
(``keyfill complete --method NAME``) and on windows of many clips at once,
``(skeleton, quats (B, T, J, 4), root (B, T, 3), keys) -> (quats, root)`` (the
benchmark protocols); :data:`BASELINES` lists both by the method's name.

* ``linear``: lerp of translations, shortest-path slerp of rotations (the
  LaFAN1 benchmark's "interpolation").
* ``cubic``: C1 cubic Hermite curves through the keys with Catmull-Rom style
  tangents for uneven key spacing (at key ``i``, the slopes of the two
  neighbouring segments weighted by the length of the other one; one-sided
  at the ends). Translations use them directly. Rotations use the same
  construction in the log map: on the segment from key ``i`` to ``i+1``,
  ``q(u) = q_i * exp(v(u))`` where ``v`` is the Hermite cubic from 0 to
  ``log(q_i^-1 q_i+1)`` whose end tangents are the key angular velocities
  (mapped through the inverse right Jacobian of SO(3)), so the angular
  velocity is continuous across keys.
* ``velocity``: the interpolation plus the velocity of given frames next to a
  gap, fading over :data:`VELOCITY_FRAMES` frames (where two keys are
  consecutive frames, their difference is a velocity the gap starts or ends with).
* ``zero-velocity``: every frame holds the last key before it.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.motion import Keys, Motion

#: frames over which :func:`velocity` lets the given frames' velocity fade (chosen on held-out styles,
#: docs/transformer.md)
VELOCITY_FRAMES = 3.0


#: frames per block of the baselines' per-frame arithmetic: its temporaries stay a few MB for a few dozen
#: joints, whatever the motion's length (:func:`in_blocks`; :mod:`keyfill.learn.exact_keys` too)
BLOCK = 4096


def in_blocks(num_frames: int, evaluate, out: tuple[np.ndarray, np.ndarray] | None = None):
    """``(rotations (F, ...), positions (F, ...))`` made :data:`BLOCK` frames at a time by
    ``evaluate(first, end) -> (rotations, positions)`` of the frames ``first .. end - 1``, into ``out`` when
    given (an ``evaluate`` that reads the same frames of ``out`` may so work in place), else new arrays."""
    rot, pos = out if out is not None else (None, None)
    for a in range(0, max(num_frames, 1), BLOCK):
        b = min(num_frames, a + BLOCK)
        r, p = evaluate(a, b)
        if rot is None:
            rot, pos = np.empty((num_frames,) + r.shape[1:]), np.empty((num_frames,) + p.shape[1:])
        rot[a:b], pos[a:b] = r, p
    return rot, pos


def segment_coordinates(num_frames: int, key_frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For every frame, the segment index ``s`` (keys ``s``, ``s+1``) and ``u`` in [0, 1].

    Frames before the first key get ``(0, 0)``; after the last key ``(K-2, 1)``.
    Returns ``(s (F,) int, u (F,) float)``.
    """
    k = np.asarray(key_frames)
    f = np.clip(np.arange(num_frames), k[0], k[-1])
    s = np.clip(np.searchsorted(k, f, side="right") - 1, 0, len(k) - 2)
    u = (f - k[s]) / (k[s + 1] - k[s])
    return s, u


def at_times(rotations: np.ndarray, positions: np.ndarray, t) -> tuple[np.ndarray, np.ndarray]:
    """Poses at fractional frame times: slerp of the rotations and lerp of the translations between the two
    frames around each time (resampling, retiming).

    Args:
        rotations: ``(F, ..., 4)`` unit quaternions, signs continuous along the first axis.
        positions: ``(F, ..., 3)`` translations.
        t: ``(N,)`` frame times, clipped to ``[0, F - 1]``; a whole time gives its frame (the
            rotations renormalised, so equal to rounding).

    Returns:
        ``(rotations (N, ..., 4), positions (N, ..., 3))``, float64.
    """
    t = np.clip(np.asarray(t, dtype=np.float64), 0, len(rotations) - 1)
    a = np.floor(t).astype(np.int64)
    b = np.minimum(a + 1, len(rotations) - 1)
    w = t - a
    rot = R.quat_slerp(rotations[a], rotations[b], w.reshape(w.shape + (1,) * (rotations.ndim - 2)))
    w = w.reshape(w.shape + (1,) * (positions.ndim - 1))
    return rot, positions[a] + w * (positions[b] - positions[a])


def _tangents(slopes: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Key tangents (K, ...) from segment slopes (K-1, ...) and segment lengths (K-1,)."""
    K = len(h) + 1
    out = np.empty((K,) + slopes.shape[1:])
    out[0], out[-1] = slopes[0], slopes[-1]
    if K > 2:
        hl = h[:-1].reshape((-1,) + (1,) * (slopes.ndim - 1))
        hr = h[1:].reshape(hl.shape)
        out[1:-1] = (hr * slopes[:-1] + hl * slopes[1:]) / (hl + hr)
    return out


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def inverse_right_jacobian(phi: np.ndarray) -> np.ndarray:
    """``J_r^-1(phi)`` of SO(3), ``(..., 3, 3)``: maps body angular velocity to d(phi)/dt."""
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = theta < 1e-6
    t = np.where(small, 1.0, theta)
    coef = np.where(small, 1 / 12 + theta**2 / 720, 1 / t**2 - (1 + np.cos(t)) / (2 * t * np.sin(t)))
    K = _skew(phi)
    return np.eye(3) + 0.5 * K + coef * (K @ K)


def _hermite(u: np.ndarray):
    u2, u3 = u * u, u * u * u
    return 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2


def _keep_keys(out_rot, out_pos, motion: Motion, keys: Keys) -> Motion:
    k = keys.frames
    out_rot[k] = motion.rotations[k]
    out_pos[k] = motion.positions[k]
    return motion.replace(rotations=out_rot, positions=out_pos, keys=keys)


def linear(motion: Motion, keys: Keys) -> Motion:
    """Lerp translations and slerp rotations between the keys of ``motion``."""
    k = keys.frames
    s, u = segment_coordinates(motion.num_frames, k)

    def frames(a, b):
        ss, uu = s[a:b], u[a:b]
        p0, p1 = motion.positions[k[ss]], motion.positions[k[ss + 1]]
        q0, q1 = motion.rotations[k[ss]], motion.rotations[k[ss + 1]]
        return R.quat_slerp(q0, q1, np.broadcast_to(uu[:, None], q0.shape[:2])), p0 + uu[:, None, None] * (p1 - p0)

    rot, pos = in_blocks(motion.num_frames, frames)
    return _keep_keys(rot, pos, motion, keys)


def cubic_arrays(rotations: np.ndarray, positions: np.ndarray, key_frames) -> tuple[np.ndarray, np.ndarray]:
    """C1 cubic Hermite splines through the key frames of ``rotations (F, N, 4)`` and ``positions (F, M, 3)``.

    Each of the ``N`` rotation and ``M`` position tracks is a curve of its own (joints, or joints of many
    windows side by side); only the key frames are read. Frames before the first key and after the last
    get the end keys (the last up to the sign of the quaternion). Key frames are *not* copied: see
    :func:`cubic`.
    """
    k = np.asarray(key_frames)
    s, u = segment_coordinates(len(rotations), k)
    h = np.diff(k).astype(np.float64)  # (K-1,)
    P = positions[k]  # (K, M, 3)
    m = _tangents(np.diff(P, axis=0) / h[:, None, None], h)  # key tangents
    Q = R.quat_continuous_np(rotations[k], axis=0)
    phi = R.quat_to_rotvec(R.quat_mul(R.quat_conjugate(Q[:-1]), Q[1:]))  # (K-1, N, 3)
    omega = _tangents(phi / h[:, None, None], h)  # body angular velocity at keys (K, N, 3)
    end_tangent = np.einsum("kjab,kjb->kja", inverse_right_jacobian(phi), omega[1:])  # (K-1, N, 3)

    def frames(a, b):
        ss = s[a:b]
        hf = h[ss][:, None, None]
        h00, h10, h01, h11 = (c[:, None, None] for c in _hermite(u[a:b]))
        pos = h00 * P[ss] + h10 * hf * m[ss] + h01 * P[ss + 1] + h11 * hf * m[ss + 1]
        v = h01 * phi[ss] + h10 * hf * omega[ss] + h11 * hf * end_tangent[ss]
        return R.quat_normalize(R.quat_mul(Q[ss], R.quat_from_rotvec(v))), pos

    return in_blocks(len(rotations), frames)


def velocity_arrays(rotations: np.ndarray, positions: np.ndarray, key_frames, frames: float):
    """Interpolation that starts and ends a gap with the velocity of the given frames next to it.

    ``rotations (F, N, 4)`` and ``positions (F, M, 3)`` are tracks as in :func:`cubic_arrays`; only
    key frames are read. On the segment from key ``a`` to key ``b`` (``h = b - a`` frames, ``u`` in
    [0, 1]) the LERP of translations (and, in the log map at ``a``, the SLERP of rotations) gets

    * ``(v_a - d) * g_a``, where ``v_a`` is the velocity into ``a`` (when frame ``a - 1`` is given),
      ``d`` the segment's mean velocity and ``g_a = frames * (1 - exp(-(t - a) / frames)) * (1 - u)^2``;
    * ``(d - v_b) * g_b`` at the other end (when frame ``b + 1`` is given), ``g_b`` the mirror image.

    So the curve leaves ``a`` (and reaches ``b``) with the given frames' velocity, which fades over
    about ``frames`` frames instead of lasting the whole gap: it moves the curve off the interpolation by
    at most ``frames`` frames' worth of the velocity difference, and the ``(1 - u)^2`` factor blends that
    out by the other key, which is met exactly. As ``frames`` grows it becomes the cubic Hermite curve
    with those end tangents (the basis terms ``h * h10`` and ``-h * h11``); where no neighbouring frame
    is given it is the LERP/SLERP.
    """
    k = np.asarray(key_frames)
    F, K = len(rotations), len(k)
    s, u = segment_coordinates(F, k)
    h = np.diff(k).astype(np.float64)  # (K-1,)
    f = np.clip(np.arange(F), k[0], k[-1])
    has_in = np.zeros(K - 1, dtype=bool)
    has_out = np.zeros(K - 1, dtype=bool)
    has_in[1:] = h[:-1] == 1  # the frame before the segment's first key is given
    has_out[:-1] = h[1:] == 1  # the frame after its last key is given
    g_in = np.where(has_in[s], frames * -np.expm1(-(f - k[s]) / frames) * (1 - u) ** 2, 0.0)[:, None, None]
    g_out = np.where(has_out[s], frames * -np.expm1(-(k[s + 1] - f) / frames) * u**2, 0.0)[:, None, None]
    seg = np.arange(K - 1)
    prev, nxt = np.maximum(seg - 1, 0), np.minimum(seg + 1, K - 2)  # neighbouring segments (unused when absent)
    U = u[:, None, None]

    P = positions[k]  # (K, M, 3)
    d = np.diff(P, axis=0) / h[:, None, None]  # (K-1, M, 3) mean velocity per segment
    pos = P[s] + U * (P[s + 1] - P[s])
    Q = rotations[k]  # each segment starts at its key's own sign, as SLERP does (rotation vectors ignore it)
    phi = R.quat_to_rotvec(R.quat_mul(R.quat_conjugate(Q[:-1]), Q[1:]))  # (K-1, N, 3)
    w_mean = phi / h[:, None, None]
    v = U * phi[s]
    if has_in.any():
        pos = pos + g_in * (d[prev[s]] - d[s])
        v = v + g_in * (w_mean[prev[s]] - w_mean[s])
    if has_out.any():  # the end tangent in the log map at the segment's first key, per segment
        end_tangent = np.einsum("kjab,kjb->kja", inverse_right_jacobian(phi), w_mean[nxt])
        pos = pos + g_out * (d[s] - d[nxt[s]])
        v = v + g_out * (w_mean[s] - end_tangent[s])
    return R.quat_normalize(R.quat_mul(Q[s], R.quat_from_rotvec(v))), pos


def cubic(motion: Motion, keys: Keys) -> Motion:
    """C1 cubic Hermite splines through the keys (translations and log-map rotations)."""
    rot, pos = cubic_arrays(motion.rotations, motion.positions, keys.frames)
    return _keep_keys(rot, pos, motion, keys)


def cubic_span(motion: Motion, k: np.ndarray, key_rotations: np.ndarray, a: int, b: int):
    """``(rotations (b - a, J, 4), positions (b - a, J, 3))``: frames ``a .. b-1`` (``a < b``) of :func:`cubic`
    of ``motion`` through its keys ``k (K,)``, made from the keys around them alone (a gap's piece of the spline
    depends on its keys and their neighbours), so a long take's spline can be made a span at a time;
    ``key_rotations (K, J, 4)``: the keys' rotations with the signs the whole spline gives them (continuous
    along the keys). Frames outside the keys take the spline's end values; key frames are the keys."""
    frames = np.clip(np.arange(a, b), k[0], k[-1])
    s = np.clip(np.searchsorted(k, frames, side="right") - 1, 0, len(k) - 2)
    lo, hi = max(int(s[0]) - 1, 0), min(int(s[-1]) + 2, len(k) - 1)
    first, window = int(k[lo]), k[lo: hi + 1] - int(k[lo])
    wr = np.empty((window[-1] + 1,) + motion.rotations.shape[1:])
    wp = np.empty((window[-1] + 1,) + motion.positions.shape[1:])
    wr[window], wp[window] = key_rotations[lo: hi + 1], motion.positions[k[lo: hi + 1]]
    spline_r, spline_p = cubic_arrays(wr, wp, window)
    rot, pos = spline_r[frames - first], spline_p[frames - first]
    at = k[(k >= a) & (k < b)]
    rot[at - a], pos[at - a] = motion.rotations[at], motion.positions[at]
    return rot, pos


def velocity(motion: Motion, keys: Keys, frames: float | None = None) -> Motion:
    """The interpolation plus the velocity of given frames next to each gap, fading over ``frames`` frames
    (:data:`VELOCITY_FRAMES` by default; :func:`velocity_arrays`)."""
    frames = VELOCITY_FRAMES if frames is None else frames
    rot, pos = velocity_arrays(motion.rotations, motion.positions, keys.frames, frames)
    return _keep_keys(rot, pos, motion, keys)


def hold(motion: Motion, keys: Keys) -> Motion:
    """Zero velocity: every frame holds the last key at or before it (frames before the first key hold it)."""
    k = keys.frames
    s, _ = segment_coordinates(motion.num_frames, k)
    src = np.where(np.arange(motion.num_frames) >= k[-1], k[-1], k[s])
    return _keep_keys(motion.rotations[src], motion.positions[src], motion, keys)


# --- the same baselines on windows of many clips at once (the benchmark protocols) ---------------

def hold_windows(skeleton, quats: np.ndarray, root: np.ndarray, keys) -> tuple[np.ndarray, np.ndarray]:
    """Hold the previous key (for in-betweening: the last context frame) until the next key."""
    k = np.asarray(keys, dtype=np.int64)
    s, _ = segment_coordinates(quats.shape[1], k)
    src = np.where(np.arange(quats.shape[1]) >= k[-1], k[-1], k[s])
    return quats[:, src].copy(), root[:, src].copy()


def _hold_outside(q: np.ndarray, r: np.ndarray, quats: np.ndarray, root: np.ndarray, k: np.ndarray):
    """Copy the key frames of ``quats``, ``root`` into ``q``, ``r`` (in place) and hold the end keys outside them."""
    src = np.clip(np.arange(quats.shape[1]), k[0], k[-1])
    held = src != np.arange(quats.shape[1])
    held[k] = True
    copy = np.flatnonzero(held)  # keys, and frames that hold one (np.union1d would import numpy.ma: 9 ms)
    q[:, copy], r[:, copy] = quats[:, src[copy]], root[:, src[copy]]
    return q, r


def linear_windows(skeleton, quats: np.ndarray, root: np.ndarray, keys) -> tuple[np.ndarray, np.ndarray]:
    """LERP the root and SLERP the local quaternions between the nearest keys.

    For in-betweening this is the protocol's interpolation from the last
    context frame to the target with weights ``linspace(0, 1, n + 2)[1:-1]``.
    Frames outside the keys hold the nearest key; key frames are copied. Only
    key frames are read. ``quats (B, T, J, 4)``, ``root (B, T, 3)``.
    """
    k = np.asarray(keys, dtype=np.int64)
    s, u = segment_coordinates(quats.shape[1], k)
    a, b = k[s], k[s + 1]
    r = root[:, a] + u[:, None] * (root[:, b] - root[:, a])
    q0 = quats[:, a]
    q = R.quat_slerp(q0, quats[:, b], np.broadcast_to(u[:, None], q0.shape[:-1]))
    return _hold_outside(q, r, quats, root, k)


def _spline_windows(spline, quats: np.ndarray, root: np.ndarray, keys, *args) -> tuple[np.ndarray, np.ndarray]:
    """``spline(rotations (F, N, 4), positions (F, M, 3), keys, *args)`` of :mod:`keyfill.interpolate`
    on all windows at once (every joint of every window a track), then keys copied and ends held as
    :func:`linear_windows` does."""
    k = np.asarray(keys, dtype=np.int64)
    B, T, J, _ = quats.shape
    q, r = spline(quats.transpose(1, 0, 2, 3).reshape(T, B * J, 4), root.transpose(1, 0, 2), k, *args)
    return _hold_outside(q.reshape(T, B, J, 4).transpose(1, 0, 2, 3), r.transpose(1, 0, 2), quats, root, k)


def cubic_windows(skeleton, quats: np.ndarray, root: np.ndarray, keys) -> tuple[np.ndarray, np.ndarray]:
    """keyfill's C1 cubic spline through every given frame (:func:`cubic_arrays`).

    All windows at once; frames outside the keys hold the nearest key and key
    frames are copied, as in :func:`linear_windows`. Only key frames are read.
    ``quats (B, T, J, 4)``, ``root (B, T, 3)``.
    """
    return _spline_windows(cubic_arrays, quats, root, keys)


def velocity_windows(skeleton, quats: np.ndarray, root: np.ndarray, keys,
                     frames: float = VELOCITY_FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """Interpolation that carries the velocity of given frames next to a gap into it, fading over
    ``frames`` frames (:func:`velocity_arrays`); windows, keys and ends as
    :func:`cubic_windows`."""
    return _spline_windows(velocity_arrays, quats, root, keys, frames)


#: every baseline by its method name (``keyfill complete --method``, ``keyfill evaluate``, the protocols):
#: ``(motion function, windows function)``; :mod:`keyfill.learn.registry` registers each as a method
BASELINES = {
    "zero-velocity": (hold, hold_windows),
    "linear": (linear, linear_windows),
    "cubic": (cubic, cubic_windows),
    "velocity": (velocity, velocity_windows),
}
