"""The one data type that flows through keyfill: ``Skeleton``, ``Motion``, ``Keys``.

A :class:`Motion` holds whole arrays, never per-frame objects:

* ``rotations (F, J, 4)``: local unit quaternions (w, x, y, z) per frame and joint;
* ``positions (F, J, 3)``: local translations in the file's units; equal to the
  skeleton's rest ``offsets`` for joints whose translation is not animated.

Frame ``i`` is at time ``i / fps`` seconds. A :class:`Skeleton` also keeps what
is needed to write a file back the way it came (per-joint BVH channel layout,
End Sites, units and up axis).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError, UsageError
from keyfill.kinematics import fk

#: deepest joint hierarchy keyfill reads (joint paths in USD grow with the depth)
MAX_DEPTH = 1000
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
#: the rotation channels of a joint that has none to keep: the order of mocap BVH (CMU, LaFAN1, Bandai)
FULL_ROTATIONS = ("Zrotation", "Xrotation", "Yrotation")
#: the channels of a root (or a translating joint) and of any other joint where a file records no BVH layout
FULL_ROOT_CHANNELS = POSITION_CHANNELS + FULL_ROTATIONS
FULL_CHANNELS = FULL_ROTATIONS
_CANONICAL = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}


def unique_names(names: Sequence[str], fallbacks: Sequence[str]) -> list[str]:
    """Joint names from a file's node names: runs of white space become ``_``, an empty name its entry of
    ``fallbacks``, and a name seen before gets ``_1``, ``_2``, ... (glTF and FBX nodes may share names)."""
    out, used = [], set()
    for raw, fallback in zip(names, fallbacks):
        base = "_".join(str(raw).split()) or fallback
        name, k = base, 1
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        out.append(name)
    return out


def canonical_channel(name: str) -> str:
    """``"xROTATION"`` -> ``"Xrotation"``; raises ``ValueError`` for unknown names."""
    try:
        return _CANONICAL[name.lower()]
    except KeyError:
        raise ValueError(
            f"unknown channel {name!r}; expected one of {', '.join(POSITION_CHANNELS + ROTATION_CHANNELS)}"
        ) from None


def check_channels(channels: Sequence[str]) -> tuple[str, ...]:
    """Validate one joint's channel list and return it in canonical spelling.

    A joint has at most one channel per axis and kind, and 0, 1, 2, 3 or 6
    channels in all (4 and 5 occur in no BVH exporter and are refused).
    """
    out = tuple(canonical_channel(c) for c in channels)
    if len(set(out)) != len(out):
        raise ValueError(f"repeated channel in {' '.join(out)}")
    if len(out) in (4, 5):
        raise ValueError(f"{len(out)} channels ({' '.join(out)}); a joint has 0, 1, 2, 3 or 6")
    return out


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy and its rest pose.

    Attributes:
        names: ``J`` joint names (unique; any characters but whitespace).
        parents: ``(J,)`` int parent index per joint, ``-1`` for roots; ``parents[j] < j``.
        offsets: ``(J, 3)`` rest translation of each joint in its parent's frame.
        channels: per joint, its BVH channel names in file order (e.g.
            ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``).
        end_sites: ``(joint index, (3,) offset)`` for each BVH End Site.
        meters_per_unit: size of one unit of ``offsets`` and positions in meters.
        up_axis: ``"Y"`` or ``"Z"``.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: tuple[tuple[int, np.ndarray], ...] = ()
    meters_per_unit: float = 0.01
    up_axis: str = "Y"

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        J = len(names)
        if J == 0:
            raise DataError("a skeleton needs at least one joint")
        if parents.shape != (J,) or offsets.shape != (J, 3):
            raise DataError(f"skeleton arrays disagree: {J} names, parents {parents.shape}, offsets {offsets.shape}")
        if len(set(names)) != J:
            dup = next(n for n in names if names.count(n) > 1)
            raise DataError(f"joint name {dup!r} appears twice")
        bad = [j for j in range(J) if not (-1 <= parents[j] < j)]
        if bad:
            raise DataError(f"joint {names[bad[0]]!r}: its parent must come before it")
        depth = np.zeros(J, dtype=np.int64)
        for j in range(J):
            if parents[j] >= 0:
                depth[j] = depth[parents[j]] + 1
                if depth[j] > MAX_DEPTH:
                    raise DataError(
                        f"joint {names[j]!r} is {depth[j]} joints deep; keyfill reads hierarchies up to {MAX_DEPTH} deep"
                    )
        if len(self.channels) != J:
            raise DataError(f"{len(self.channels)} channel lists for {J} joints")
        channels = tuple(check_channels(c) for c in self.channels)
        ends = tuple((int(j), np.asarray(o, dtype=np.float64).reshape(3)) for j, o in self.end_sites)
        if self.up_axis not in ("Y", "Z"):
            raise DataError(f"up axis must be Y or Z, not {self.up_axis!r}")
        if not np.all(np.isfinite(offsets)) or not self.meters_per_unit > 0:
            raise DataError("skeleton offsets must be finite and the unit positive")
        offsets.setflags(write=False)
        parents.setflags(write=False)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "end_sites", ends)

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def to_json(self, hierarchy_only: bool = False) -> dict:
        """This skeleton as JSON (what a model folder's ``config.json`` records of the skeleton it serves).

        ``names``, ``parents`` and ``offsets`` (in the skeleton's units); unless ``hierarchy_only``, also
        ``channels`` (per joint, its BVH channel names), ``up_axis`` and ``meters_per_unit``. End sites
        are not recorded. :meth:`from_json` reads either form back.
        """
        out = {"names": list(self.names), "parents": [int(p) for p in self.parents], "offsets": self.offsets.tolist()}
        if not hierarchy_only:
            out.update({"channels": [list(c) for c in self.channels], "up_axis": self.up_axis,
                        "meters_per_unit": self.meters_per_unit})
        return out

    @classmethod
    def from_json(cls, data: dict) -> Skeleton:
        """The skeleton :meth:`to_json` wrote, in either form (a hierarchy only: no channels, Y up, cm).

        A ``KeyError`` when the full form lacks a field; a :class:`DataError` when the values do not make a
        skeleton."""
        names = data["names"]
        if "channels" not in data:
            return cls(names=tuple(names), parents=data["parents"], offsets=data["offsets"],
                       channels=tuple(() for _ in names))
        channels = data["channels"]
        if not (isinstance(channels, list) and all(isinstance(c, list) and all(isinstance(n, str) for n in c)
                                                   for c in channels)):
            raise DataError("skeleton channels must be a list of lists of channel names")
        if not isinstance(data["up_axis"], str) or type(data["meters_per_unit"]) not in (int, float):
            raise DataError("skeleton up_axis must be a string and meters_per_unit a number")
        return cls(names=tuple(names), parents=data["parents"], offsets=data["offsets"],
                   channels=tuple(tuple(c) for c in channels), up_axis=data["up_axis"],
                   meters_per_unit=data["meters_per_unit"])

    def index(self, name: str) -> int:
        """Index of joint ``name``; the error lists the valid names."""
        try:
            return self.names.index(name)
        except ValueError:
            raise UsageError(f"unknown joint {name!r}; joints are: {', '.join(self.names)}") from None

    @functools.cached_property
    def euler_orders(self) -> tuple[str, ...]:
        """Per joint, the intrinsic Euler order of its rotation channels (worked out once per skeleton:
        callers index it per joint, which for 10,000 joints made ``info`` quadratic).

        Joints with fewer than three rotation channels get the missing axes
        appended (their angles are zero in the file).
        """
        orders = []
        for chans in self.channels:
            axes = "".join(c[0] for c in chans if c in ROTATION_CHANNELS)
            orders.append(axes + "".join(a for a in "XYZ" if a not in axes))
        return tuple(orders)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def children(self, j: int) -> list[int]:
        return [int(k) for k in np.flatnonzero(self.parents == j)]

    def rest_world_positions(self) -> np.ndarray:
        """``(J, 3)`` world joint positions with identity rotations and rest offsets."""
        ident = np.zeros((self.num_joints, 4))
        ident[:, 0] = 1
        return fk(ident, self.offsets, self.parents)[1]

    def difference(self, other: Skeleton, atol: float = 1e-6) -> str | None:
        """A one-line description of the first difference from ``other``, or None."""
        if self.num_joints != other.num_joints:
            n = min(self.num_joints, other.num_joints)
            j = next((j for j in range(n) if self.names[j] != other.names[j]), n)
            a = repr(self.names[j]) if j < self.num_joints else "none"
            b = repr(other.names[j]) if j < other.num_joints else "none"
            return f"{self.num_joints} joints vs {other.num_joints}; the first that differs is joint {j}, {a} vs {b}"
        for j in range(self.num_joints):
            if self.names[j] != other.names[j]:
                return f"joint {j} is {self.names[j]!r} vs {other.names[j]!r}"
            if self.parents[j] != other.parents[j]:
                return f"joint {self.names[j]!r} has a different parent"
            if not np.allclose(self.offsets[j], other.offsets[j], atol=atol):
                return f"joint {self.names[j]!r} has a different rest offset"
        return None

    def replace(self, **changes) -> Skeleton:
        return dataclasses.replace(self, **changes)

    @property
    def has_full_layout(self) -> bool:
        """Whether every joint has three rotation channels and zero or three position channels, and every root
        three: the BVH layout that Blender's importer, bvhio and pymotion all take (Blender refuses a joint
        with fewer than three rotation channels)."""
        for chans, parent in zip(self.channels, self.parents):
            n_pos = sum(c in POSITION_CHANNELS for c in chans)
            if sum(c in ROTATION_CHANNELS for c in chans) != 3 or n_pos not in (0, 3) or (parent < 0 and n_pos != 3):
                return False
        return True

    def full_layout(self, translating: Iterable[int] = ()) -> Skeleton:
        """This skeleton with the channel layout of :attr:`has_full_layout`, holding the same motion.

        A joint keeps its rotation order, completed with the missing axes (whose
        angles it never had, so they are zero: :attr:`euler_orders`); a joint
        without rotation channels gets :data:`FULL_ROTATIONS`. Roots, joints
        with any position channel and the joints ``translating`` (indices) get
        ``Xposition Yposition Zposition`` first (an axis without a channel
        before holds the OFFSET's value).
        """
        translating = set(translating)
        channels = []
        for j, (chans, parent, order) in enumerate(zip(self.channels, self.parents, self.euler_orders)):
            has_rotation = any(c in ROTATION_CHANNELS for c in chans)
            rotations = tuple(f"{axis}rotation" for axis in order) if has_rotation else FULL_ROTATIONS
            moves = parent < 0 or j in translating or any(c in POSITION_CHANNELS for c in chans)
            channels.append((POSITION_CHANNELS if moves else ()) + rotations)
        return self.replace(channels=tuple(channels))


#: what a keyed joint gives at a key (:attr:`Keys.given`): its local channels, its 3-D position, or the
#: two coordinates of its position in a view plane (world axes, file units)
KEY_GIVEN = ("pose", "position", "XY", "XZ", "YZ")


@dataclass(frozen=True, eq=False)
class Keys:
    """Keyframe indices of a motion, and for partial keys which joints and values each key gives.

    Attributes:
        frames: ``(K,)`` strictly increasing non-negative frame indices.
        mask: optional ``(K, J)`` bool, which joints are keyed at each key
            (``None``: all joints at every key).
        given: what a keyed joint gives (one of :data:`KEY_GIVEN`): ``"pose"`` (the
            default) its local rotation and translation, so its position follows by
            forward kinematics when its ancestors are keyed too; ``"position"`` only
            its 3-D position (the root's: a spot on the path); ``"XY"``, ``"XZ"`` or
            ``"YZ"`` only the two coordinates of its world position in that view plane
            (2-D keys, as a sketch in a front or top view). The values themselves are
            those of the motion at the key frames.

    Keys are *partial* (:attr:`partial`) when some joint is unkeyed somewhere or
    when they give less than a pose; only methods whose registry entry says so
    accept them (:mod:`keyfill.learn.registry`).
    """

    frames: np.ndarray
    mask: np.ndarray | None = field(default=None)
    given: str = "pose"

    def __post_init__(self) -> None:
        frames = np.asarray(self.frames, dtype=np.int64).reshape(-1)
        if np.any(frames < 0):
            raise UsageError(f"key {int(frames[frames < 0][0])} is negative")
        d = np.diff(frames)
        if np.any(d == 0):
            raise UsageError(f"key {int(frames[1:][d == 0][0])} appears twice")
        if np.any(d < 0):
            i = int(np.flatnonzero(d < 0)[0])
            raise UsageError(f"keys must be in increasing order: {int(frames[i])} comes before {int(frames[i + 1])}")
        frames.setflags(write=False)
        object.__setattr__(self, "frames", frames)
        if self.mask is not None:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.ndim != 2 or mask.shape[0] != len(frames):
                raise UsageError(f"key mask of shape {mask.shape} for {len(frames)} keys")
            mask.setflags(write=False)
            object.__setattr__(self, "mask", mask)
        given = self.given.upper() if self.given.upper() in KEY_GIVEN else self.given.lower()
        if given not in KEY_GIVEN:
            raise UsageError(f"unknown view plane or key content {self.given!r}; keys give one of: "
                             f"{', '.join(KEY_GIVEN)}")
        object.__setattr__(self, "given", given)

    @property
    def partial(self) -> bool:
        """True when some key leaves a joint unkeyed or the keys give less than whole poses."""
        return self.given != "pose" or (self.mask is not None and not bool(self.mask.all()))

    def joint_mask(self, num_joints: int) -> np.ndarray:
        """``(K, J)`` bool: the keyed joints of each key (all when :attr:`mask` is None)."""
        if self.mask is None:
            return np.ones((len(self.frames), num_joints), dtype=bool)
        if self.mask.shape[1] != num_joints:
            raise UsageError(f"the key mask names {self.mask.shape[1]} joints; the motion has {num_joints}")
        return self.mask

    def coordinate_mask(self, num_joints: int) -> np.ndarray:
        """``(K, J, 3)`` bool: the world position coordinates each key gives (all three, or a plane's two)."""
        axes = np.ones(3, dtype=bool) if self.given in ("pose", "position") else \
            np.array([a in self.given for a in "XYZ"])
        return self.joint_mask(num_joints)[..., None] & axes

    def channel_masks(self, skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
        """``(rotation (K, J), translation (K, J, 3))`` bool: the local channels the keys fix.

        With ``given="pose"`` a keyed joint fixes its rotation and translation. Positions
        are world values: with ``"position"`` or a plane, a keyed joint whose channels
        hold a position (the root; Bandai-Namco's hips below a static top joint) fixes its
        translation in the given coordinates; other joints' positions are not channels,
        so they are met by the method, not fixed.
        """
        J = skeleton.num_joints
        joints = self.joint_mask(J)
        if self.given == "pose":
            return joints, np.repeat(joints[..., None], 3, axis=-1)
        movable = np.array([any(c in POSITION_CHANNELS for c in chans) for chans in skeleton.channels])
        movable[0] = True
        trans = self.coordinate_mask(J) & movable[None, :, None]
        return np.zeros_like(joints), trans

    def restrict(self, skeleton: Skeleton, joints: Sequence[str] | None = None, given: str = "pose") -> Keys:
        """These key frames, keying only the joints named ``joints`` (all when None) at every key, giving ``given``.

        ``keys.restrict(sk, [sk.names[0]], "position")`` is a path of root spots (the
        paper's 5.1); a list of the legs' joints is a half-body key (5.2);
        ``given="XY"`` gives 2-D keys in the XY view plane (5.3). An unknown joint
        name is a :class:`UsageError` listing the skeleton's joints.
        """
        mask = None
        if joints is not None:
            if not joints:
                raise UsageError("partial keys need at least one keyed joint")
            row = np.zeros(skeleton.num_joints, dtype=bool)
            row[[skeleton.index(n) for n in joints]] = True
            mask = np.repeat(row[None], len(self.frames), axis=0)
        return Keys(self.frames, mask, given)

    def select(self, index) -> Keys:
        """The keys ``index`` (an index array or a bool array over the keys) with their mask rows."""
        mask = None if self.mask is None else self.mask[index]
        return Keys(self.frames[index], mask, self.given)

    def __len__(self) -> int:
        return len(self.frames)

    @classmethod
    def parse(cls, text: str, *, param: str = "text") -> Keys:
        """Keys from ``"0,12,30"`` (the ``--keys`` option); errors name the parameter ``param``."""
        try:
            frames = [int(t) for t in text.replace(" ", "").split(",") if t != ""]
        except ValueError:
            raise UsageError(f"{param} takes frame numbers separated by commas, like 0,12,30; got {text!r}",
                             params=param) from None
        huge = [f for f in frames if abs(f) >= 2**63]
        if huge:
            raise UsageError(f"key {huge[0]} is out of range")
        return cls(np.array(frames, dtype=np.int64))

    @classmethod
    def every(cls, step: int, num_frames: int, *, param: str = "step") -> Keys:
        """A key every ``step`` frames from frame 0, plus the last frame; errors name the parameter ``param``."""
        if step < 1:
            raise UsageError(f"{param} must be at least 1, got {step}", params=param)
        frames = np.arange(0, num_frames, step)
        if num_frames > 0 and frames[-1] != num_frames - 1:
            frames = np.append(frames, num_frames - 1)
        return cls(frames)

    def check(self, num_frames: int, min_keys: int = 2) -> Keys:
        """Raise a :class:`UsageError` unless the keys fit a motion of ``num_frames`` frames."""
        if len(self.frames) < min_keys:
            raise UsageError(f"at least {min_keys} keys are needed, got {len(self.frames)}")
        if len(self.frames) and self.frames[-1] >= num_frames:
            raise UsageError(
                f"key {int(self.frames[-1])} is out of range: the motion has {num_frames} frames (0-{num_frames - 1})"
            )
        return self

    def to_list(self) -> list[int]:
        return [int(f) for f in self.frames]

    @classmethod
    def resolve(cls, motion: Motion, keys_text: str | None = None, key_every: int | None = None,
                min_keys: int = 2) -> Keys:
        """The keys for ``motion``: from ``keys_text`` (``"0,12,30"``), a key every ``key_every`` frames, or else
        the motion's own keys. Errors name the parameters ``keys_text`` and ``key_every`` (in ``params``)."""
        if keys_text is not None and key_every is not None:
            raise UsageError("give keys_text or key_every, not both", params=("keys_text", "key_every"))
        if keys_text is not None:
            keys = cls.parse(keys_text, param="keys_text")
        elif key_every is not None:
            keys = cls.every(key_every, motion.num_frames, param="key_every")
        elif motion.keys is not None:
            keys = motion.keys
        else:
            raise UsageError("this file records no keys; give keys_text (e.g. 0,12,30) or key_every N",
                             params=("keys_text", "key_every"))
        return keys.check(motion.num_frames, min_keys=min_keys)


#: frames per block of :meth:`Motion.euler_blocks`: its temporaries are a few MB for a few dozen joints
EULER_BLOCK = 4096
#: frames a Motion checks for values that are not finite at once
FINITE_BLOCK = 65_536


def _turns_off(angles: np.ndarray) -> np.ndarray:
    """Distance of ``angles`` (radians) from the nearest whole number of turns."""
    return np.abs((angles + np.pi) % (2 * np.pi) - np.pi)


@dataclass(frozen=True, eq=False)
class Motion:
    """Skeletal animation as arrays.

    Attributes:
        skeleton: the :class:`Skeleton`.
        fps: frames per second (> 0).
        rotations: ``(F, J, 4)`` float64 local unit quaternions (w, x, y, z).
        positions: ``(F, J, 3)`` float64 local translations, file units.
        keys: the keyframes, when the file or the caller defines them.
    """

    skeleton: Skeleton
    fps: float
    rotations: np.ndarray
    positions: np.ndarray
    keys: Keys | None = None

    def __post_init__(self) -> None:
        rot = np.asarray(self.rotations, dtype=np.float64)
        pos = np.asarray(self.positions, dtype=np.float64)
        J = self.skeleton.num_joints
        if rot.ndim != 3 or rot.shape[1:] != (J, 4):
            raise DataError(f"rotations must be (frames, {J}, 4), got {rot.shape}")
        if pos.shape != rot.shape[:2] + (3,):
            raise DataError(f"positions must be {rot.shape[:2] + (3,)}, got {pos.shape}")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise DataError(f"fps must be positive, got {self.fps}")
        for a in range(0, len(rot), FINITE_BLOCK):  # a block at a time: no whole-take temporary per Motion
            r, p = rot[a : a + FINITE_BLOCK], pos[a : a + FINITE_BLOCK]
            if not (np.all(np.isfinite(r)) and np.all(np.isfinite(p))):
                f = a + int(np.flatnonzero(~(np.isfinite(r).all(axis=(1, 2)) & np.isfinite(p).all(axis=(1, 2))))[0])
                raise DataError(f"frame {f} holds a value that is not finite")
        if self.keys is not None:
            self.keys.check(rot.shape[0], min_keys=0)
        object.__setattr__(self, "rotations", rot)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "fps", float(self.fps))

    @property
    def num_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def num_joints(self) -> int:
        return self.skeleton.num_joints

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return max(self.num_frames - 1, 0) / self.fps

    def world(self) -> tuple[np.ndarray, np.ndarray]:
        """World ``(rotations (F, J, 4), positions (F, J, 3))`` by forward kinematics."""
        return fk(self.rotations, self.positions, self.skeleton.parents)

    def world_positions(self) -> np.ndarray:
        """World joint positions ``(F, J, 3)``."""
        return self.world()[1]

    def euler_angles(self) -> np.ndarray:
        """``(F, J, 3)`` radians: each joint's rotation as its channels hold it.

        Angles are intrinsic in the joint's :attr:`Skeleton.euler_orders`, and
        continuous over time as animation curves should be: no whole-turn jumps
        and no flips between the two Euler solutions of a rotation. For a joint
        with fewer than three rotation channels the missing (trailing) angles
        are zero; a rotation about an axis without a channel raises
        :class:`DataError` naming the joint and frame. Made by :meth:`euler_blocks`.
        """
        angles = np.empty((self.num_frames, self.skeleton.num_joints, 3))
        for start, block in self.euler_blocks():
            angles[start : start + len(block)] = block
        return angles

    def euler_blocks(self, block: int = EULER_BLOCK):
        """:meth:`euler_angles` a block of frames at a time: ``(first frame, (b, J, 3) radians)`` per block.

        Each block continues the curves of the one before it (it is made continuous from that block's last
        frame), so a writer can stream any number of frames with temporaries of ``block`` frames.
        """
        sk = self.skeleton
        J = sk.num_joints
        orders = sk.euler_orders
        n_rot = np.array([sum(c in ROTATION_CHANNELS for c in chans) for chans in sk.channels])
        full = n_rot == 3
        groups = [(order, [j for j in range(J) if orders[j] == order]) for order in sorted(set(orders))]
        last = None  # (J, 3) the previous block's last frame
        for start in range(0, self.num_frames, block):
            angles = np.empty((min(block, self.num_frames - start), J, 3))
            for order, js in groups:
                angles[:, js] = R.quat_to_euler(self.rotations[start : start + len(angles), js], order)
            if last is None:
                angles[:, full] = R.euler_continuous_np(angles[:, full])
            else:  # continue from the last frame: it stays first, and the whole turns it was moved by come back
                turns = 2 * np.pi * np.round(last[full] / (2 * np.pi))
                angles[:, full] = R.euler_continuous_np(np.concatenate([last[None, full], angles[:, full]]))[1:] + turns
            for j in np.flatnonzero(~full):
                angles[:, j] = self._partial_joint(j, int(n_rot[j]), angles[:, j], start, None if last is None else last[j])
            last = angles[-1].copy()
            yield start, angles

    def _partial_joint(self, j: int, n: int, a: np.ndarray, start: int, last) -> np.ndarray:
        """The ``(b, 3)`` angles ``a`` (frames from ``start``) of joint ``j`` with ``n`` < 3 rotation channels,
        as :meth:`euler_angles` gives them: continuing from ``last`` ((3,) or None)."""
        # Of the two Euler solutions, take the one whose missing angles are zero.
        alt = np.stack([a[:, 0] + np.pi, np.pi - a[:, 1], a[:, 2] + np.pi], axis=-1)
        use_alt = _turns_off(alt[:, n:]).sum(axis=1) < _turns_off(a[:, n:]).sum(axis=1)
        a = np.where(use_alt[:, None], alt, a)
        missing = _turns_off(a[:, n:])
        if missing.size and missing.max() > 1e-6:
            f = start + int(np.argmax(missing.max(axis=1)))
            chans = " ".join(self.skeleton.channels[j]) or "none"
            raise DataError(
                f"joint {self.skeleton.names[j]!r} rotates about an axis that its channels ({chans}) cannot hold, "
                f"at frame {f}"
            )
        a[:, n:] = 0.0
        if last is None:
            return np.unwrap(a, axis=0)
        return np.unwrap(np.concatenate([last[None], a]), axis=0)[1:]

    def replace(self, **changes) -> Motion:
        return dataclasses.replace(self, **changes)

    def frames(self, index: slice | Iterable[int]) -> Motion:
        """A motion of the selected frames (keys outside the selection are dropped)."""
        idx = np.arange(self.num_frames)[index] if isinstance(index, slice) else np.asarray(list(index))
        keys = None
        if self.keys is not None:
            lookup = {int(f): i for i, f in enumerate(idx)}
            inside = np.array([int(f) in lookup for f in self.keys.frames], dtype=bool)
            kept = self.keys.select(inside)
            order = np.argsort([lookup[int(f)] for f in kept.frames], kind="stable")
            keys = Keys(np.array([lookup[int(f)] for f in kept.frames], dtype=np.int64)[order],
                        None if kept.mask is None else kept.mask[order], kept.given)
        return self.replace(rotations=self.rotations[idx], positions=self.positions[idx], keys=keys)

    @classmethod
    def rest(cls, skeleton: Skeleton, num_frames: int = 1, fps: float = 30.0) -> Motion:
        """A motion that holds the rest pose for ``num_frames`` frames."""
        rot = np.zeros((num_frames, skeleton.num_joints, 4))
        rot[..., 0] = 1
        pos = np.broadcast_to(skeleton.offsets, (num_frames, skeleton.num_joints, 3)).copy()
        return cls(skeleton, fps, rot, pos)
