"""Feet on the ground: foot contact labels and foot locking for any humanoid rig.

Foot joints. Per side (``l`` then ``r``) the ankle (role ``foot``) and, where the rig has one, the toe (role
``toe``): :func:`contact_joints` lists them in the column order of every contact array here,
``foot_l, toe_l, foot_r, toe_r`` (a rig without toes has no toe columns).

Contacts (:func:`contacts`, :func:`label_contacts`). Sizes are fractions of the rig's hip height ``H``
(:attr:`keyfill.characters.retarget.Rig.hip_height`, in the skeleton's units), so one rule serves rigs in cm,
in m and CMU's 24-unit-tall ones; speeds are in ``H`` per second, so it serves any frame rate. Heights are
along the skeleton's up axis (Y or Z), speeds horizontal (the other two axes): on each frame the slower of the
step from the frame before and the step to the frame after, so a foot that arrives or leaves on a frame is
still on it.

* The ground is ``ground`` when given, else the lowest height of any foot joint over the key frames (over all
  frames without keys): keys are real poses, generated frames between them may sink through the floor.
* A joint's *planted height* is the ground plus its own lowest height above the ground over those frames (an
  ankle sits above the sole, a toe less so), at most :attr:`FootSettings.ankle_sole_max` or
  :attr:`FootSettings.toe_sole_max` (so a foot that never comes down is not called planted at its lowest).
* Hysteresis: a joint *enters* contact on a frame where it is at most ``height_enter`` above its planted
  height and slower than ``speed_enter``; it *stays* in contact while it is at most ``height_leave`` above and
  slower than ``speed_leave``. Then contact intervals shorter than ``min_contact_s`` are dropped.

Locking (:func:`lock_feet`, in the manner of Kovar, Schreiner and Gleicher 2002, "Footskate cleanup"). In
each contact interval a foot joint stays at one world position: the key's where the interval holds a key
(several: linearly between their positions), else the interval's median. The foot keeps its world
orientation, so the held joint places the other: where the toe is in contact it is held (the foot pivots
about it as the heel lifts) and the ankle follows; where only the ankle is (the heel strikes first) the
ankle is held (``lock_toes=False``: ankles only). The lock's offset at an interval's first and last frame is
eased in before it and out after it over ``ease_s`` with a smoothstep weight, so the result is continuous
and the free path only shifts. Each leg is solved for its ankle's target by
:func:`keyfill.kinematics.two_bone_ik`, the knee bending to the side it bends to in the motion. Where a leg
cannot reach (beyond ``max_reach`` of its length) the hips come down along the up axis by what it lacks,
smoothed, at most ``max_hip_drop``; a free leg then keeps its ankle where it was. Only the local rotations of
thighs, shins and feet and the hips' translation change, so bone lengths stay exact. Frames of ``keys`` come
back bit-identical: at a key in an interval the lock is the key's own position, and an ease that would reach
over a key is shortened to end at it, so every correction is zero at the keys by construction.

Quaternions are (w, x, y, z), Hamilton product (:mod:`keyfill.rotations`); positions in the skeleton's units.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from keyfill import rotations as R
from keyfill.characters.humanoid import SIDES
from keyfill.characters.legs import BLOCK, ancestors, chain_world, leg_chain, leg_world, solve_legs
from keyfill.characters.retarget import Rig, make_rig
from keyfill.errors import DataError, UsageError
from keyfill.motion import POSITION_CHANNELS, Keys, Motion, Skeleton

_AXES = {"X": 0, "Y": 1, "Z": 2}
_LEG_ROLES = ("thigh", "shin", "foot")


@dataclass(frozen=True)
class FootSettings:
    """Thresholds of foot contacts and of foot locking. Sizes are fractions of the rig's hip height ``H``
    (``H`` ~ 0.8-1.0 m for an adult), speeds in ``H`` per second, lengths in seconds (any frame rate).

    Attributes:
        height_enter: ``0.03 H`` (~2.5 cm): a joint this close to its planted height may enter contact;
            the 2.5 cm of :func:`keyfill.learn.protocols.metrics.foot_skating` at ``H`` = 0.82 m (Bandai).
        height_leave: ``0.05 H`` (~4 cm): above this it leaves contact (a heel lifting off rises past it
            within a frame or two; the gap to ``height_enter`` absorbs generated jitter).
        speed_enter: ``0.5 H/s`` (~40 cm/s): slower than this it may enter contact. A planted foot of a real
            clip moves a few cm/s (heel-to-toe roll), a generated one slides at 30-60 cm/s and should still be
            caught, a swinging foot near the ground moves at 2-4 m/s.
        speed_leave: ``0.8 H/s`` (~65 cm/s): faster than this it leaves contact (a real toe pushing off passes
            it; held longer, the leg would have to stretch and the hips come down).
        min_contact_s: ``0.1 s``: shorter contacts are dropped (3 frames at 30 fps: a foot passing low
            through the threshold is no step; a real stance lasts 0.3 s or more even when running).
        ease_s: ``0.2 s`` (6 frames at 30 fps): the lock is blended in before and out after each contact
            over this long; shorter looks like a snap, longer drags the foot after lift-off.
        ankle_sole_max: ``0.15 H``: the highest an ankle may sit above the ground when planted (a human
            ankle is at ~0.1 H standing); :func:`contacts` takes the data's, at most this.
        toe_sole_max: ``0.06 H``: the same for a toe joint (~2-3 cm above the ground standing).
        max_reach: ``0.999``: the furthest a leg is stretched, as a fraction of its length, before the hips
            come down (a fully straight knee pops).
        max_hip_drop: ``0``: the most the hips come down to let a leg reach, in ``H`` (beyond it the foot
            gives: the leg points straight at its target, and the report counts the frame as unreached). Off
            by default: on held-out clips (benchmarks/bench_feet.py; docs/feet.md) every drop tried (0.02, 0.05,
            0.1 H) raised the gap error (up to 1.17x the raw output's at keys every 60 frames, against 1.07x
            without) and lowered foot skating by no more.
        lock_toes: ``True``: hold a toe wherever it is in contact, the ankle following the foot (the heel
            lifts about it); False holds the ankles only, the toes following.
    """

    height_enter: float = 0.03
    height_leave: float = 0.05
    speed_enter: float = 0.5
    speed_leave: float = 0.8
    min_contact_s: float = 0.1
    ease_s: float = 0.2
    ankle_sole_max: float = 0.15
    toe_sole_max: float = 0.06
    max_reach: float = 0.999
    max_hip_drop: float = 0.0
    lock_toes: bool = True

    def __post_init__(self):
        for name in (f.name for f in fields(self) if f.name != "lock_toes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0 or value == math.inf:
                raise UsageError(f"{name} must be a number of at least 0, got {value!r}", params=name)
        if self.height_enter > self.height_leave:
            raise UsageError(f"height_enter ({self.height_enter}) must not exceed height_leave "
                             f"({self.height_leave})", params=("height_enter", "height_leave"))
        if self.speed_enter > self.speed_leave:
            raise UsageError(f"speed_enter ({self.speed_enter}) must not exceed speed_leave ({self.speed_leave})",
                             params=("speed_enter", "speed_leave"))
        if not 0 < self.max_reach <= 1:
            raise UsageError(f"max_reach must be in (0, 1], got {self.max_reach}", params="max_reach")

    def min_contact_frames(self, fps: float) -> int:
        """``min_contact_s`` in frames at ``fps`` (at least 1)."""
        return max(1, round(self.min_contact_s * fps))

    def ease_frames(self, fps: float) -> int:
        """``ease_s`` in frames at ``fps`` (0: no easing)."""
        return max(0, round(self.ease_s * fps))


# --- the legs of a rig --------------------------------------------------------------------------------------


def _as_rig(rig: Rig | Skeleton) -> Rig:
    """``rig``, or the :class:`Rig` of a skeleton; a skeleton without legs is a :class:`DataError`."""
    if isinstance(rig, Rig):
        return rig
    if not isinstance(rig, Skeleton):
        raise UsageError(f"rig must be a Rig or a Skeleton, not {type(rig).__name__}", params="rig")
    try:
        return make_rig(rig)
    except DataError:
        from keyfill.characters import humanoid  # which of the legs' roles the mapper found

        found = humanoid._find(humanoid._Rig(rig, "the skeleton"), {})
        missing = [r for r in ("hips", *(f"{r}_{s}" for s in SIDES for r in _LEG_ROLES)) if found.get(r) is None]
        if not missing:
            raise
        raise DataError(f"the skeleton has no legs to put on the ground: found no joint for the roles "
                        f"{', '.join(missing)}; name them in a rig_map and make the Rig with it",
                        params="rig_map") from None


def foot_chains(rig: Rig | Skeleton) -> dict[str, tuple[int, int, int, int | None]]:
    """Per side (``"l"``, ``"r"``) the joint indices ``(thigh, shin, foot, toe)`` of the leg; ``toe`` is None
    where the rig has no toe role. A skeleton is made a :class:`Rig` first.

    Raises :class:`DataError` naming the missing roles when a leg is missing, or when the roles do not make
    a chain (each joint below the one before it).
    """
    rig = _as_rig(rig)
    limbs, parents = rig.roles.limbs, rig.skeleton.parents
    missing = [f"{r}_{s}" for s in SIDES for r in _LEG_ROLES if f"{r}_{s}" not in limbs]
    if missing:
        raise DataError(f"the rig has no legs to put on the ground: it lacks the roles {', '.join(missing)}; "
                        f"name them in a rig_map and make the Rig with it", params="rig_map")
    out = {s: tuple([limbs[f"{r}_{s}"] for r in _LEG_ROLES] + [limbs.get(f"toe_{s}")]) for s in SIDES}
    for s, chain in out.items():
        for upper, lower in itertools.pairwise(j for j in chain if j is not None):
            if upper not in ancestors(parents, lower):
                names = rig.skeleton.names
                raise DataError(f"the {s} leg is not a chain: {names[lower]!r} is not below {names[upper]!r}",
                                params="rig_map")
    return out


def contact_joints(rig: Rig | Skeleton) -> list[tuple[str, int]]:
    """``[(role, joint index), ...]``: the foot joints, in the column order of every contact array:
    ``foot_l``, ``toe_l``, ``foot_r``, ``toe_r`` (toes only where the rig has them)."""
    out = []
    for s, (_, _, foot, toe) in foot_chains(rig).items():
        out.append((f"foot_{s}", foot))
        if toe is not None:
            out.append((f"toe_{s}", toe))
    return out


def _motion_rig(motion: Motion, rig: Rig | Skeleton) -> Rig:
    """:func:`_as_rig` of ``rig``, checked to be ``motion``'s skeleton."""
    rig = _as_rig(rig)
    if motion.skeleton is not rig.skeleton and motion.skeleton.names != rig.skeleton.names:
        raise DataError("the motion is not on the rig's skeleton (their joints differ)")
    return rig


def _frames(keys, num_frames: int, param: str = "keys") -> np.ndarray:
    """The key frame indices of ``keys`` (a :class:`Keys`, a sequence of ints or None: none), checked."""
    if keys is None:
        return np.zeros(0, dtype=np.int64)
    frames = np.asarray(keys.frames if isinstance(keys, Keys) else keys, dtype=np.int64).reshape(-1)
    bad = frames[(frames < 0) | (frames >= num_frames)]
    if len(bad):
        raise UsageError(f"key {int(bad[0])} is out of range: the motion has {num_frames} frames", params=param)
    return np.unique(frames)


def _ground_value(ground) -> float | None:
    if ground is None:
        return None
    try:
        value = float(ground)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise UsageError(f"ground must be a finite number (a height along the up axis), got {ground!r}",
                         params="ground")
    return value


# --- contacts -------------------------------------------------------------------------------------------------


def ground_height(motion: Motion, rig: Rig | Skeleton, keys: Keys | Sequence[int] | None = None,
                  ground: float | None = None) -> float:
    """The ground's height along the skeleton's up axis (skeleton units): ``ground`` when given, else the
    lowest height of any foot joint (:func:`contact_joints`) over the frames of ``keys``, else over all frames."""
    value = _ground_value(ground)
    if value is not None:
        return value
    rig = _motion_rig(motion, rig)
    frames = _frames(keys, motion.num_frames)
    if motion.num_frames == 0:
        raise DataError("the motion has no frames to find the ground in")
    idx = frames if len(frames) else slice(None)
    feet = [j for _, j in contact_joints(rig)]
    _, pos, column = leg_world(motion.rotations[idx], motion.positions[idx], motion.skeleton, feet)
    return float(pos[:, column[feet], _AXES[motion.skeleton.up_axis]].min())


def _planted_heights(feet: np.ndarray, roles: list[str], ref: np.ndarray, ground: float | None, up: int,
                     hip_height: float, settings: FootSettings) -> tuple[np.ndarray, float]:
    """``((n,) planted height per foot joint, ground)`` from foot positions ``(F, n, 3)`` (module docstring)."""
    h = feet[ref if len(ref) else slice(None), :, up]
    auto = float(h.min())
    caps = np.array([settings.toe_sole_max if r.startswith("toe") else settings.ankle_sole_max for r in roles])
    sole = np.clip(h.min(axis=0) - auto, 0.0, caps * hip_height)
    g = auto if ground is None else ground
    return g + sole, g


def label_contacts(positions, floor, *, fps: float, up_axis: str, hip_height, settings: FootSettings = FootSettings()
                   ) -> np.ndarray:
    """Contact labels ``(..., F, n)`` bool of foot joint world positions ``(..., F, n, 3)`` (the rule in the
    module docstring; any leading batch shape, e.g. windows of a training corpus).

    Args:
        positions: ``(..., F, n, 3)`` world positions of ``n`` foot joints over ``F`` frames.
        floor: each joint's planted height along the up axis, broadcasting against ``(..., n)``.
        fps: frames per second.
        up_axis: ``"Y"`` or ``"Z"``.
        hip_height: the rig's hip height ``H`` (skeleton units), a number or ``(...)`` per sequence.
        settings: the thresholds.
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim < 3 or p.shape[-1] != 3:
        raise UsageError(f"positions must be (..., frames, joints, 3), got {p.shape}", params="positions")
    up = _AXES[up_axis]
    scale = np.asarray(hip_height, dtype=np.float64)[..., None, None]
    floor = np.broadcast_to(np.asarray(floor, dtype=np.float64), p.shape[:-3] + p.shape[-2:-1])
    height = p[..., up] - floor[..., None, :]
    F = p.shape[-3]
    flat = p[..., [a for a in range(3) if a != up]]
    step = np.linalg.norm(np.diff(flat, axis=-3), axis=-1) * fps  # (..., F-1, n)
    pad = np.full(step.shape[:-2] + (1,) + step.shape[-1:], np.inf)
    speed = np.minimum(np.concatenate([pad, step], axis=-2), np.concatenate([step, pad], axis=-2))
    speed = np.where(np.isinf(speed), 0.0, speed)  # a single frame
    enter = (height <= settings.height_enter * scale) & (speed <= settings.speed_enter * scale)
    stay = (height <= settings.height_leave * scale) & (speed <= settings.speed_leave * scale)
    enter &= stay
    # in contact on t: staying in contact, and it entered since the last frame it could not stay
    idx = np.arange(F).reshape((F, 1))
    last_out = np.maximum.accumulate(np.where(stay, -1, idx), axis=-2)
    last_in = np.maximum.accumulate(np.where(enter, idx, -1), axis=-2)
    state = stay & (last_in > last_out)
    return _drop_short(state, settings.min_contact_frames(fps))


def _drop_short(state: np.ndarray, min_frames: int) -> np.ndarray:
    """``state (..., F, n)`` without its runs of True shorter than ``min_frames`` (along ``F``)."""
    if min_frames <= 1 or state.size == 0:
        return state
    x = np.moveaxis(state, -2, -1).reshape(-1, state.shape[-2])  # (B, F)
    B, F = x.shape
    edges = np.diff(np.pad(x.astype(np.int8), ((0, 0), (1, 1))), axis=1)  # +1 at starts, -1 past ends
    (rows, starts), (_, ends) = np.nonzero(edges == 1), np.nonzero(edges == -1)
    short = ends - starts < min_frames
    marks = np.zeros((B, F + 1), dtype=np.int64)
    np.add.at(marks, (rows[short], starts[short]), 1)
    np.add.at(marks, (rows[short], ends[short]), -1)
    keep = x & (np.cumsum(marks[:, :F], axis=1) == 0)
    shape = state.shape[:-2] + (state.shape[-1], F)
    return np.moveaxis(keep.reshape(shape), -1, -2)


def contacts(motion: Motion, rig: Rig | Skeleton, ground: float | None = None,
             keys: Keys | Sequence[int] | None = None, settings: FootSettings = FootSettings()) -> np.ndarray:
    """Contact labels ``(F, n)`` bool of ``motion``'s foot joints, in the order of :func:`contact_joints`.

    ``ground``: the ground's height along the up axis (skeleton units), else found from the frames of ``keys``
    (else all frames) as :func:`ground_height` does. The rule and the defaults: the module docstring and
    :class:`FootSettings`. Pure: the same motion gives the same labels (corpus labels come from here too).
    """
    rig = _motion_rig(motion, rig)
    sk, cols = motion.skeleton, contact_joints(rig)
    if motion.num_frames == 0:
        return np.zeros((0, len(cols)), dtype=bool)
    joints = [j for _, j in cols]
    _, pos, column = leg_world(motion.rotations, motion.positions, sk, joints)
    feet = pos[:, column[joints]]
    floor, _ = _planted_heights(feet, [r for r, _ in cols], _frames(keys, motion.num_frames), _ground_value(ground),
                                _AXES[sk.up_axis], rig.hip_height, settings)
    return label_contacts(feet, floor, fps=motion.fps, up_axis=sk.up_axis, hip_height=rig.hip_height,
                          settings=settings)


# --- locking ------------------------------------------------------------------------------------------------


def _runs(column: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last frame (inclusive) of each run of True in a ``(F,)`` bool array."""
    edges = np.diff(np.pad(column.astype(np.int8), 1))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1


def _lock_offsets(p: np.ndarray, label: np.ndarray, keys: np.ndarray, ease: int,
                  free: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """The eased lock of one joint: ``(offset (F, 3) from p to its target, weight (F,) in [0, 1], intervals)``.

    ``p (F, 3)``: the joint's free world positions; ``label (F,)``: its contacts. In an interval the target is
    the keys' positions (linear between several) or the median of ``p`` (over the frames where ``free`` < 1,
    when given and there are any); before and after, the offset at the interval's first or last frame is
    blended in with a weight that eases from 0 to 1 over ``ease`` frames, or
    fewer where a key is nearer (the weight is 0 at every key outside the interval). Overlapping eases are
    averaged by weight, so the offset is continuous.
    """
    F = len(p)
    starts, ends = _runs(label)
    if len(starts) == 0:
        return np.zeros((F, 3)), np.zeros(F), 0
    # every (interval, frame) pair of the intervals and their eases, all intervals at once
    i0, i1 = np.searchsorted(keys, starts), np.searchsorted(keys, ends, side="right")  # the keys inside: i0:i1
    before = np.where(i0 > 0, starts - keys[np.maximum(i0 - 1, 0)] - 1, ease)  # frames after the key before
    after = np.where(i1 < len(keys), keys[np.minimum(i1, len(keys) - 1)] - ends - 1, ease)
    ease_in, ease_out = np.minimum(ease, before), np.minimum(ease, after)
    lo, hi = np.maximum(0, starts - ease_in), np.minimum(F - 1, ends + ease_out)
    seg, t = _spans(lo, hi)
    s, e = starts[seg], ends[seg]
    x = np.where(t < s, 1 - (s - t) / (ease_in[seg] + 1), np.where(t > e, 1 - (t - e) / (ease_out[seg] + 1), 1.0))
    w = x * x * (3 - 2 * x)
    inside = np.clip(t, s, e)  # the eases blend the offset at the interval's ends
    target = np.empty((len(t), 3))
    count = (i1 - i0)[seg]
    one = count == 1
    target[one] = p[keys[i0[seg[one]]]]
    many = count > 1
    if np.any(many):  # linear between the keys, (1 - u) a + u b: exactly a key's position at the key
        tm, sm = inside[many], seg[many]
        j = np.clip(np.searchsorted(keys, tm, side="right") - 1, i0[sm], i1[sm] - 2)
        u = np.clip((tm - keys[j]) / (keys[j + 1] - keys[j]), 0.0, 1.0)[:, None]  # held beyond the end keys
        target[many] = (1 - u) * p[keys[j]] + u * p[keys[j + 1]]
    none = count == 0
    if np.any(none):
        target[none] = _medians(p, starts, ends, i1 - i0 == 0, free)[seg[none]]
    offset = w[:, None] * (target - p[inside])
    total = np.stack([np.bincount(t, weights=offset[:, c], minlength=F) for c in range(3)], axis=-1)
    weight = np.bincount(t, weights=w, minlength=F)
    return total / np.maximum(weight, 1.0)[:, None], np.minimum(weight, 1.0), len(starts)


def _ankle_offsets(feet: np.ndarray, labels: np.ndarray, column: dict, side: str, has_toe: bool, keys: np.ndarray,
                   ease: int, lock_toes: bool) -> tuple[np.ndarray, int]:
    """``(offset (F, 3), intervals)``: where the ankle of ``side`` must move for its foot's locks, and how many
    contact intervals they hold. ``feet (F, n, 3)``, ``labels (F, n)``: the foot joints' positions and
    contacts, joint ``role`` in column ``column[role]``. With a toe (and ``lock_toes``) the toe is held first
    and the ankle where the toe is not; else the ankle alone (the toe's intervals still counted)."""
    ankle_label, ankle = labels[:, column[f"foot_{side}"]], feet[:, column[f"foot_{side}"]]
    if has_toe and lock_toes:
        off_toe, w_toe, n = _lock_offsets(feet[:, column[f"toe_{side}"]], labels[:, column[f"toe_{side}"]], keys, ease)
        off_ankle, _, m = _lock_offsets(ankle + off_toe, ankle_label, keys, ease, free=w_toe)
        return off_toe + (1 - w_toe)[:, None] * off_ankle, n + m
    off, _, n = _lock_offsets(ankle, ankle_label, keys, ease)
    return off, n + (len(_runs(labels[:, column[f"toe_{side}"]])[0]) if has_toe else 0)


def _spans(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(span index, frame)`` of every frame of the spans ``lo[i]..hi[i]`` (inclusive), span after span."""
    n = hi - lo + 1
    seg = np.repeat(np.arange(len(n)), n)
    return seg, np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + lo[seg]


def _medians(p: np.ndarray, starts: np.ndarray, ends: np.ndarray, wanted: np.ndarray,
             free: np.ndarray | None) -> np.ndarray:
    """``(I, 3)``: per interval (where ``wanted``), the median of ``p (F, 3)`` over its frames, or over those where
    ``free < 1`` when there are any."""
    seg, f = _spans(starts, ends)
    keep = wanted[seg]
    if free is not None:
        sel = free[f] < 1
        some = np.bincount(seg, weights=sel, minlength=len(starts)) > 0
        keep &= sel | ~some[seg]
    seg, f, out = seg[keep], f[keep], np.zeros((len(starts), 3))
    n = np.bincount(seg, minlength=len(starts))
    first, has = np.cumsum(n) - n, n > 0
    for c in range(3):
        v = p[f, c][np.lexsort((p[f, c], seg))]  # sorted within each interval
        out[has, c] = 0.5 * (v[(first + (n - 1) // 2)[has]] + v[(first + n // 2)[has]])
    return out


def _key_fade(frames: np.ndarray, num_frames: int, ease: int) -> np.ndarray:
    """``(F,)``: 0 at ``frames`` (sorted), rising smoothly to 1 at ``ease + 1`` frames from the nearest of them."""
    if len(frames) == 0:
        return np.ones(num_frames)
    t = np.arange(num_frames)
    i = np.searchsorted(frames, t)
    left, right = frames[np.clip(i - 1, 0, len(frames) - 1)], frames[np.clip(i, 0, len(frames) - 1)]
    x = np.minimum(1.0, np.minimum(np.abs(t - left), np.abs(right - t)) / (ease + 1))
    return x * x * (3 - 2 * x)  # smoothstep


def _hip_drop(targets, thighs, reach, up: int, cap: float) -> np.ndarray:
    """``(F,)`` how far the hips must come down so each leg reaches its target (legs stacked on axis 1):
    the least ``d >= 0`` with ``|target - (thigh - d up)| <= reach``, at most ``cap``."""
    v = targets - thighs  # (F, 2, 3)
    vu, n2 = v[..., up], np.sum(v * v, axis=-1)
    disc = vu * vu - n2 + reach * reach
    need = np.where(disc >= 0, -vu - np.sqrt(np.maximum(disc, 0)), -vu)
    need = np.where(n2 <= reach * reach, 0.0, need)
    return np.clip(need, 0.0, cap).max(axis=1)


def _smooth_drop(need: np.ndarray, ease: int, fade: np.ndarray) -> np.ndarray:
    """``need`` widened (a running max over ``2r``) and smoothed (two running means over ``r``): never less
    than ``need`` (each mean's window lies inside the max's), continuous; faded to ``need`` at the keys."""
    from scipy.ndimage import maximum_filter1d, uniform_filter1d

    if not np.any(need > 0):
        return need
    r = max(ease, 1)
    m = maximum_filter1d(need, size=4 * r + 1, mode="nearest")
    smooth = uniform_filter1d(uniform_filter1d(m, 2 * r + 1, mode="nearest"), 2 * r + 1, mode="nearest")
    return np.maximum(need, smooth * fade)


def _skating(feet: np.ndarray, labels: np.ndarray, up: int, fps: float) -> float | None:
    """Mean horizontal speed (units/s) of foot joints ``(F, n, 3)`` over frame pairs in contact on both."""
    both = labels[1:] & labels[:-1]
    if not both.any():
        return None
    step = np.empty(both.shape)
    flat = [a for a in range(3) if a != up]
    for a in range(0, len(step), BLOCK):  # in blocks: the temporaries stay small
        step[a : a + BLOCK] = np.linalg.norm(np.diff(feet[a : a + BLOCK + 1][..., flat], axis=0), axis=-1)
    return float(step[both].mean() * fps)


def lock_feet(motion: Motion, rig: Rig | Skeleton, keys: Keys | Sequence[int] | None = None,
              ground: float | None = None, settings: FootSettings = FootSettings(),
              labels: np.ndarray | None = None, in_place: bool = False) -> tuple[Motion, dict]:
    """``motion`` with its feet held still in ground contact (the module docstring), and a report.

    Args:
        motion: the motion (any humanoid rig, fps, units, Y- or Z-up).
        rig: its :class:`Rig` (or its skeleton, made a rig with the roles found in it).
        keys: the frames that must stay exact (a :class:`Keys` or frame indices); None: ``motion.keys``.
            They also give the ground (:func:`ground_height`).
        ground: the ground's height along the up axis, else found from the keys.
        settings: thresholds, easing and reach (:class:`FootSettings`).
        labels: ``(F, n)`` bool contacts to use (the columns of :func:`contact_joints`); default
            :func:`contacts` of the motion.
        in_place: lock in ``motion``'s own arrays (which the result then holds) instead of copies: for a
            caller that made them and lets ``motion`` go (a long take needs no second copy).

    Returns:
        ``(locked motion, report)``. The report: ``skating_before`` and ``skating_after``, the mean horizontal
        speed of the foot joints over frame pairs in contact (by ``labels``), in the motion's units per
        second (None without contacts; ``meters_per_unit`` converts); ``intervals`` (contact intervals of all
        foot joints); ``frames_in_contact`` (frames where some foot joint is in contact); ``frames_changed``;
        ``hip_drop_max`` (units); ``unreached_frames`` (frames where an ankle misses its target by more than
        1e-6 of the hip height: the hips' drop was capped); ``ground``; ``meters_per_unit``.
    """
    rig = _motion_rig(motion, rig)
    sk, F, fps = motion.skeleton, motion.num_frames, motion.fps
    up, H = _AXES[sk.up_axis], rig.hip_height
    key_frames = _frames(motion.keys if keys is None else keys, F)
    chains, cols = foot_chains(rig), contact_joints(rig)
    column = {role: i for i, (role, _) in enumerate(cols)}
    if F == 0:
        raise DataError("the motion has no frames to lock the feet of")
    # the whole take holds only per-frame arrays of the feet; the legs' kinematics are made a block of frames
    # at a time, where needed (issue 44: 0.3x the motion's memory at most, not 1.3x)
    chain = leg_chain(sk, [j for c in chains.values() for j in c if j is not None])
    col = chain[2]
    feet = np.empty((F, len(cols), 3))  # (F, n, 3) world positions of the foot joints
    for a in range(0, F, BLOCK):
        feet[a : a + BLOCK] = chain_world(motion.rotations, motion.positions, chain, slice(a, a + BLOCK))[1][
            :, col[[j for _, j in cols]]]
    floor, ground_used = _planted_heights(feet, [r for r, _ in cols], key_frames, _ground_value(ground), up, H, settings)
    if labels is None:
        labels = label_contacts(feet, floor, fps=fps, up_axis=sk.up_axis, hip_height=H, settings=settings)
    elif np.shape(labels) != (F, len(cols)):
        raise UsageError(f"labels must be (frames, foot joints) = {(F, len(cols))}, got {np.shape(labels)}",
                         params="labels")
    labels = np.asarray(labels, dtype=bool)
    ease, sides = settings.ease_frames(fps), list(chains)
    locks = [_ankle_offsets(feet, labels, column, s, chains[s][3] is not None, key_frames, ease, settings.lock_toes)
             for s in sides]
    intervals = sum(n for _, n in locks)
    offsets = np.stack([off for off, _ in locks], axis=1)  # (F, 2, 3)
    del locks
    legs = np.array([chains[s][:3] for s in sides])  # (2, 3): thigh, shin, foot
    ankle_cols = [column[f"foot_{s}"] for s in sides]
    cap = settings.max_hip_drop * H
    need = np.zeros(F)  # what the hips must come down (none without a cap above 0)
    for a in range(0, F, BLOCK) if cap > 0 else ():
        _, P = chain_world(motion.rotations, motion.positions, chain, slice(a, a + BLOCK))
        thighs, knees, ankles = (P[:, col[legs[:, i]]] for i in range(3))
        length = np.linalg.norm(knees - thighs, axis=-1) + np.linalg.norm(ankles - knees, axis=-1)
        reach = np.maximum(settings.max_reach * length, np.linalg.norm(ankles - thighs, axis=-1))
        need[a : a + BLOCK] = _hip_drop(ankles + offsets[a : a + BLOCK], thighs, reach, up, cap)
    drop = _smooth_drop(need, ease, _key_fade(key_frames, F, ease))
    drop[(drop < 1e-12 * H) | np.isin(np.arange(F), key_frames)] = 0.0
    shift = -drop[:, None] * np.eye(3)[up]  # (F, 3) along the up axis
    changed = np.any(offsets != 0, axis=-1) | (drop > 0)[:, None]  # (F, 2)
    changed[key_frames] = False
    rotations, positions = (motion.rotations, motion.positions) if in_place else (motion.rotations.copy(),
                                                                                  motion.positions.copy())
    frames = np.flatnonzero(changed.any(axis=1))
    moved = feet[:, ankle_cols] + shift[:, None]  # the ankles: with the hips, then where the IK put them
    unreached = 0
    for i in range(0, len(frames), BLOCK):  # the legs' kinematics of a block of frames, before its IK
        rows = frames[i : i + BLOCK]
        W, P = chain_world(motion.rotations, motion.positions, chain, rows)
        targets = feet[rows][:, ankle_cols] + offsets[rows]
        solved = solve_legs(rotations, W, P, col, rows, legs, chains, sides, sk.parents, shift[rows], targets,
                            changed[rows])
        moved[rows] = np.where(changed[rows, :, None], solved, moved[rows])
        miss = np.linalg.norm(solved - targets, axis=-1) > 1e-6 * H
        unreached += int((miss & changed[rows]).any(axis=1).sum())
    if np.any(drop > 0):  # after the IK, which reads the legs' kinematics of the hips where they were
        mover = _translated_joint(sk, rig.roles.hips)
        parent, down = sk.parents[mover], np.flatnonzero(drop > 0)
        for i in range(0, len(down), BLOCK):
            rows = down[i : i + BLOCK]
            local = shift[rows] if parent < 0 else R.quat_rotate(
                R.quat_conjugate(chain_world(motion.rotations, motion.positions, chain, rows)[0][:, col[parent]]),
                shift[rows])
            positions[rows, mover] += local
    locked = motion.replace(rotations=rotations, positions=positions)
    skating_before = _skating(feet, labels, up, fps)
    moved -= feet[:, ankle_cols]  # how each ankle moved
    for c, (role, _) in enumerate(cols):  # the feet keep their turn: each moves as its side's ankle did
        feet[:, c] += moved[:, sides.index(role[-1])]
    report = {
        "skating_before": skating_before,
        "skating_after": _skating(feet, labels, up, fps),
        "intervals": int(intervals),
        "frames_in_contact": int(labels.any(axis=1).sum()),
        "frames_changed": len(frames),
        "hip_drop_max": float(drop.max()),
        "unreached_frames": unreached,
        "ground": ground_used,
        "meters_per_unit": sk.meters_per_unit,
    }
    return locked, report


def _translated_joint(skeleton: Skeleton, hips: int) -> int:
    """The joint whose translation moves the hips: they or their nearest ancestor with position channels."""
    return next((j for j in [hips, *ancestors(skeleton.parents, hips)]
                 if any(c in POSITION_CHANNELS for c in skeleton.channels[j])), hips)
