"""Humanoid roles: which joint of a skeleton is the hips, the spine chain, the head, each hand, ...

The shipped human models know one skeleton; every other humanoid reaches them through these roles
(:data:`ROLES`): ``hips``; the ``spine`` chain (1-n joints) and the ``neck`` chain (0-n joints), bottom to
top; ``head``; and per side (:data:`SIDES`, the character's own left and right) the limb roles
:data:`LIMB_ROLES`, named ``f"{role}_{side}"`` (``upper_arm_l``). :func:`map_roles` finds them in any common
rig and returns a :class:`RoleMap`; a TOML rig map (:func:`read_rig_map`) gives the ones it cannot find.

How the mapper decides. Names find the ends of the limbs; the hierarchy decides everything else, because
the same word names different bones in different rigs (Mixamo's ``LeftShoulder`` is the clavicle, a
joint-named rig's ``LeftShoulder`` the upper arm; Mixamo's ``LeftLeg`` is the shin, SMPL's ``L_Foot`` the
toe):

1. A name is read as lower-case tokens after any namespace prefix (up to the last ``:`` or ``|``, as in
   ``mixamorig1:``): ``LeftUpLeg`` -> left, up, leg; ``DEF-upper_arm.L.001`` -> def, upper, arm, l, 001.
   The tokens l, left, r, right give the side (also glued to a limb word: ASF's ``lhumerus``); the others,
   without digits and filler (``DEF``, ``J``, ``Bip``, ``joint``), joined, give the joint's word (``upleg``,
   ``upperarm``). A joint whose tokens say twist, roll, helper, ik, ctrl, end, nub, ... is a helper and plays
   no role.
2. Each side's hand is the top-most joint whose word is hand, wrist or palm; each foot the top-most foot or
   ankle (so SMPL's ``L_Ankle`` is the foot); the head the top-most ``head``. Where names give no side (a
   Blender ``hand`` and ``hand.001``) the rest pose decides: the character's left is the up axis crossed
   with the direction the feet point to their toes.
3. The hips are the deepest joint above both feet and the head (Bandai's ``Hips``, not ``joint_Root``; a
   hips-named joint straight above it wins, as in 3ds Max's Biped whose legs hang from ``Spine``).
   Without a head word the head is the top of the chain above the joint where the arms branch (Rigify's
   ``DEF-spine.006``).
4. Limbs are counted along the hierarchy from the hand or foot up to the torso (the path from hips to
   head): the bones above a hand are forearm, upper arm and, when there is one more, clavicle; above a
   foot shin and thigh (CMU's ``LHipJoint`` above the thigh stays unmapped); the toe is the foot's child.
   Counting skips helpers, the later segments of a split bone (Rigify's ``DEF-forearm.L.001`` continues
   ``DEF-forearm.L``) and joints whose bone has zero length (their one child sits on them). This differs
   from skipping every zero-offset joint: CMU's ``LeftShoulder`` sits on ``Spine1`` but is the clavicle.
5. The spine is the torso path from the hips up to the first neck-named joint or, without one, up to the
   highest joint an arm hangs from; the neck is the rest of the path below the head.

The rest pose is used only for the sides of step 2 where names are silent: the Bandai rig's zero pose
(every bone along its joint's local X axis) carries no body geometry, A- and T-poses differ, and up may be
Y or Z.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from keyfill import limits
from keyfill.errors import DataError, FormatError, UsageError
from keyfill.files import read_regular
from keyfill.motion import Skeleton

SIDES = ("l", "r")
LIMB_ROLES = ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe")
#: every role, in the order :meth:`RoleMap.describe` lists them; ``spine`` and ``neck`` are chains
ROLES = ("hips", "spine", "neck", "head") + tuple(f"{r}_{s}" for s in SIDES for r in LIMB_ROLES)
#: roles a human model needs; the others (clavicle, toe, neck) are optional
REQUIRED = ("hips", "head") + tuple(
    f"{r}_{s}" for s in SIDES for r in ("upper_arm", "forearm", "hand", "thigh", "shin", "foot"))
#: the single joints at the ends of the chains, for :meth:`RoleMap.joint`
CHAIN_ENDS = ("spine_bottom", "spine_top", "neck_bottom", "neck_top")
_CHAINS = ("spine", "neck")
_LIMBS = tuple(r for r in ROLES if r[-2:] in ("_l", "_r"))
_ARM = ("forearm", "upper_arm", "clavicle")  # bottom-up from the hand
_LEG = ("shin", "thigh")  # bottom-up from the foot

_SIDE_TOKENS = {"l": "l", "left": "l", "r": "r", "right": "r"}
_FILLER = {"def", "j", "jnt", "joint", "bip", "bn", "c"}
_HELPER = {"twist", "roll", "helper", "ik", "fk", "ctrl", "ctl", "control", "mch", "org", "pole", "target",
           "end", "nub", "tip", "site", "dummy", "null", "aux", "corrective"}
_HAND = {"hand", "wrist", "palm"}
_FOOT = {"foot", "ankle"}
_TOE = {"toe", "toes", "toebase", "ball"}
_CLAVICLE = {"clavicle", "collar", "collarbone", "shoulder"}
#: limb words a one-letter side may be glued to (Acclaim / CMU ASF names: ``lhumerus``, ``rfoot``)
_LIMB_WORDS = _HAND | _FOOT | _TOE | _CLAVICLE | {
    "humerus", "radius", "ulna", "femur", "tibia", "elbow", "knee", "hip", "thigh", "shin", "calf", "arm",
    "forearm", "upperarm", "lowerarm", "leg", "upleg", "upperleg", "lowerleg", "fingers", "thumb"}


@dataclass(frozen=True)
class RoleMap:
    """Which joint of a skeleton plays each humanoid role.

    Attributes:
        names: the skeleton's ``J`` joint names (to report, and to check the map against a skeleton).
        hips: joint index of the hips (pelvis), where the legs and the spine start.
        spine: joint indices strictly between the hips and the neck (or the head), bottom to top; 1-n
            joints, none only when the rig has none.
        neck: 0-n joint indices between the spine's top and the head, bottom to top.
        head: joint index of the head.
        limbs: ``f"{role}_{side}"`` (e.g. ``"upper_arm_l"``) -> joint index, in :data:`ROLES` order; optional
            roles (clavicle, toe) are absent when the rig has none. Read-only by convention.
    """

    names: tuple[str, ...]
    hips: int
    spine: tuple[int, ...]
    neck: tuple[int, ...]
    head: int
    limbs: dict[str, int]

    def __post_init__(self):
        names = tuple(str(n) for n in self.names)
        limbs = {str(k): int(v) for k, v in dict(self.limbs).items()}
        unknown = [k for k in limbs if k not in _LIMBS]
        if unknown:
            raise DataError(f"no limb role {unknown[0]!r}; limb roles are {', '.join(_LIMBS)}")
        chains = {c: tuple(int(j) for j in getattr(self, c)) for c in _CHAINS}
        owner: dict[int, str] = {}
        for role, j in [("hips", int(self.hips))] + [(c, j) for c in _CHAINS for j in chains[c]] + [
                ("head", int(self.head))] + list(limbs.items()):
            if not 0 <= j < len(names):
                raise DataError(f"role {role}: joint index {j} is outside the skeleton's {len(names)} joints")
            if j in owner:
                raise DataError(f"joint {names[j]!r} plays two roles, {owner[j]} and {role}")
            owner[j] = role
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "hips", int(self.hips))
        object.__setattr__(self, "head", int(self.head))
        object.__setattr__(self, "spine", chains["spine"])
        object.__setattr__(self, "neck", chains["neck"])
        object.__setattr__(self, "limbs", {k: limbs[k] for k in _LIMBS if k in limbs})

    def joint(self, role: str) -> int | None:
        """The joint index of one single-joint role: ``"hips"``, ``"head"``, a limb role (``"hand_l"``) or a
        chain end (:data:`CHAIN_ENDS`: ``"spine_top"``, the joint the arms and neck hang from in most rigs).
        None when the rig lacks that role; a :class:`UsageError` for a name that is no such role."""
        if role in ("hips", "head"):
            return getattr(self, role)
        if role in _LIMBS:
            return self.limbs.get(role)
        if role in CHAIN_ENDS:
            chain = self.spine if role.startswith("spine") else self.neck
            return (chain[-1] if role.endswith("top") else chain[0]) if chain else None
        raise UsageError(f"no single-joint humanoid role {role!r}; they are hips, head, "
                         f"{', '.join(CHAIN_ENDS)} and {', '.join(_LIMBS)}")

    def describe(self) -> list[str]:
        """One line ``"role: joint name"`` per role of :data:`ROLES` (chains: names joined by ``", "``;
        ``(none)`` for a role the rig lacks), for ``keyfill info --rig``."""
        lines = []
        for role in ROLES:
            if role in _CHAINS:
                text = ", ".join(self.names[j] for j in getattr(self, role))
            else:
                j = self.joint(role)
                text = "" if j is None else self.names[j]
            lines.append(f"{role}: {text or '(none)'}")
        return lines

    def to_json(self) -> dict:
        """Role -> joint name (``spine``, ``neck``: a list of names), the roles the rig has, in :data:`ROLES`
        order. It is a valid ``rig_map``: ``map_roles(skeleton, m.to_json())`` gives ``m`` back."""
        out: dict = {}
        for role in ROLES:
            if role in _CHAINS:
                out[role] = [self.names[j] for j in getattr(self, role)]
            elif (j := self.joint(role)) is not None:
                out[role] = self.names[j]
        return out


def _tokens(name: str) -> list[str]:
    """``"mixamorig1:LeftHandIndex1"`` -> ``["left", "hand", "index", "1"]``: camel case, digits and any
    non-alphanumeric character separate tokens; a namespace prefix (up to the last ``:`` or ``|``) is dropped."""
    base = re.split(r"[:|]", name)[-1]
    out: list[str] = []
    for part in re.split(r"[^0-9A-Za-z]+", base):
        out += re.findall(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|[0-9]+", part)
    return [t.lower() for t in out]


def _read_name(name: str) -> tuple[str | None, str, bool]:
    """What a joint name says: its side (``"l"``, ``"r"`` or None), its word and whether it is a helper."""
    tokens = _tokens(name)
    sides = {_SIDE_TOKENS[t] for t in tokens if t in _SIDE_TOKENS}
    word = "".join(t for t in tokens if t not in _SIDE_TOKENS and t not in _FILLER and not t.isdigit())
    if not sides:  # the side glued to the word: "Leftarm", "lhumerus"
        for prefix in ("left", "right", "l", "r"):
            rest = word[len(prefix):]
            if word.startswith(prefix) and rest and (len(prefix) > 1 or rest in _LIMB_WORDS):
                sides, word = {_SIDE_TOKENS[prefix]}, rest
                break
    return (sides.pop() if len(sides) == 1 else None), word, any(t in _HELPER for t in tokens)


class _Rig:
    """A skeleton as the mapper reads it: the hierarchy, what each name says, the rest pose."""

    def __init__(self, skeleton: Skeleton, label: str):
        self.skeleton = skeleton
        self.label = label
        J = skeleton.num_joints
        self.parents = [int(p) for p in skeleton.parents]
        self.children: list[list[int]] = [[] for _ in range(J)]
        self.depth = [0] * J
        for j, p in enumerate(self.parents):
            if p >= 0:
                self.children[p].append(j)
                self.depth[j] = self.depth[p] + 1
        self.height = [0] * J  # joints below j on its longest branch
        for j in reversed(range(J)):
            if self.parents[j] >= 0:
                self.height[self.parents[j]] = max(self.height[self.parents[j]], self.height[j] + 1)
        said = [_read_name(n) for n in skeleton.names]
        self.side = [s for s, _, _ in said]
        self.word = [w for _, w, _ in said]
        self.helper = [h for _, _, h in said]
        lengths = np.linalg.norm(skeleton.offsets, axis=1)
        self.zero = lengths <= 1e-6 * max(float(lengths.max()), 1e-12)

    def lineage(self, j: int) -> list[int]:
        """``j`` and its ancestors, bottom-up."""
        out = [j]
        while self.parents[out[-1]] >= 0:
            out.append(self.parents[out[-1]])
        return out

    def lca(self, joints: list[int]) -> int | None:
        """The deepest joint that is ``j`` or above it for every ``j`` of ``joints`` (None: different roots)."""
        common = self.lineage(joints[0])
        for j in joints[1:]:
            above = set(self.lineage(j))
            common = [a for a in common if a in above]
        return common[0] if common else None

    def up_to(self, j: int, stop: set[int]) -> tuple[list[int], int | None]:
        """The joints strictly between ``j`` and the first of its ancestors in ``stop``, bottom-up, and that
        ancestor (None when ``j`` has none in ``stop``)."""
        path, p = [], self.parents[j]
        while p >= 0 and p not in stop:
            path.append(p)
            p = self.parents[p]
        return path, (p if p >= 0 else None)

    def bones(self, path: list[int]) -> list[int]:
        """The joints of ``path`` that are limb bones: not helpers, not a later segment of their parent's bone
        (same word and side: ``DEF-forearm.L.001`` under ``DEF-forearm.L``), not a zero-length bone (one child,
        not a helper, at the joint itself: that child's bone is the limb's)."""
        out = []
        for j in path:
            kids = self.children[j]
            zero_bone = len(kids) == 1 and self.zero[kids[0]] and not (self.helper[kids[0]] or self.segment(kids[0]))
            if not (self.helper[j] or self.segment(j) or zero_bone):
                out.append(j)
        return out

    def segment(self, j: int) -> bool:
        """Whether ``j`` continues its parent's bone: the same word and side (``DEF-forearm.L.001``)."""
        p = self.parents[j]
        return p >= 0 and self.word[j] != "" and (self.word[j], self.side[j]) == (self.word[p], self.side[p])

    def is_hips(self, j: int) -> bool:
        """Whether the name says hips: ``Hips``, ``pelvis``, or ``hip`` without a side (Daz)."""
        word = self.word[j]
        return not self.helper[j] and (word in ("hips", "pelvis") or (word == "hip" and self.side[j] is None))

    @cached_property
    def world(self) -> np.ndarray:
        return self.skeleton.rest_world_positions()

    @cached_property
    def left(self) -> np.ndarray:
        """``(3,)`` the character's left in the rest pose: up (the skeleton's axis) crossed with the way the
        feet point to their toes; +X (Y up facing +Z, or Z up facing -Y) when the feet show no direction."""
        up = np.array([0.0, 1.0, 0.0]) if self.skeleton.up_axis == "Y" else np.array([0.0, 0.0, 1.0])
        forward = np.zeros(3)
        for j, word in enumerate(self.word):
            kids = [c for c in self.children[j] if not self.helper[c]]
            if word in _FOOT and not self.helper[j] and kids:
                forward += self.world[kids[0]] - self.world[j]
        forward -= up * (forward @ up)
        size = np.ptp(self.world, axis=0).max()
        if np.linalg.norm(forward) <= 1e-6 * max(size, 1e-12):
            return np.array([1.0, 0.0, 0.0])
        return np.cross(up, forward / np.linalg.norm(forward))

    def ends(self, words: set[str]) -> dict[str, int | None]:
        """Per side, the top-most non-helper joint whose word is one of ``words``; joints whose names give
        no side fill the sides that names leave empty, left or right by the rest pose."""
        cands = [j for j, w in enumerate(self.word) if w in words and not self.helper[j]]
        picks: dict[str, int | None] = {}
        for s in SIDES:
            sided = [j for j in cands if self.side[j] == s]
            picks[s] = min(sided, key=lambda j: (self.depth[j], j)) if sided else None
        free = [s for s in SIDES if picks[s] is None]
        loose = sorted((j for j in cands if self.side[j] is None
                        and not any(k != j and k in self.lineage(j) for k in cands)),
                       key=lambda j: (self.depth[j], j))
        if len(free) == 2 and len(loose) >= 2:
            picks["l"], picks["r"] = sorted(loose[:2], key=lambda j: -(self.world[j] @ self.left))
        elif len(free) == 1 and loose:
            picks[free[0]] = loose[0]
        return picks

    def top(self, start: int, avoid: set[int]) -> int | None:
        """The top of the chain that rises from ``start`` (its longest branch outside ``avoid``), following
        single children and stopping where the chain branches (a head with eyes) or ends."""
        kids = [c for c in self.children[start] if not self.helper[c] and c not in avoid]
        if not kids:
            return None
        j = max(kids, key=lambda c: (self.height[c], -c))
        while len(kids := [c for c in self.children[j] if not self.helper[c]]) == 1:
            j = kids[0]
        return j


def _assign(rig: _Rig, bones: list[int], roles: tuple[str, ...], given: dict, used: set[int],
            prefer: set[str] = frozenset()) -> dict[str, int | None]:
    """``roles`` (bottom-up) onto ``bones`` (bottom-up), one each in order; a given role keeps its joint and the
    count goes on above it. The last role takes a joint whose word is in ``prefer`` where there is one."""
    out: dict[str, int | None] = {}
    pos = 0
    for i, role in enumerate(roles):
        if role in given:
            out[role] = given[role]
            pos = bones.index(given[role]) + 1 if given[role] in bones else pos
            continue
        limit = next((bones.index(given[r]) for r in roles[i + 1:] if given.get(r) in bones), len(bones))
        cands = [b for b in bones[pos:limit] if b not in used]
        if i == len(roles) - 1:
            cands.sort(key=lambda b: rig.word[b] not in prefer)
        out[role] = cands[0] if cands else None
        pos = bones.index(cands[0]) + 1 if cands else pos
    return out


def _entries_problem(rig_map) -> str | None:
    """What is wrong with a rig map's entries as such (not with its joints), or None."""
    if not isinstance(rig_map, dict):
        return "a rig map is a table of role = joint name"
    for role, value in rig_map.items():
        if role not in ROLES:
            return f"{role!r} is no humanoid role; the roles are {', '.join(ROLES)}"
        if role in _CHAINS:
            if not (isinstance(value, str) or (isinstance(value, (list, tuple))
                                               and all(isinstance(v, str) for v in value))):
                return f"{role} must be a list of joint names, not {value!r}"
        elif not isinstance(value, str):
            return f"{role} must be one joint name, not {value!r}"
    return None


def _given(skeleton: Skeleton, rig_map, label: str) -> dict:
    """``rig_map`` checked against the skeleton: role -> joint index (chains: a tuple of indices)."""
    if not rig_map:
        return {}
    problem = _entries_problem(rig_map)
    if problem:
        raise UsageError(f"rig_map: {problem}", params="rig_map")
    index = {n: i for i, n in enumerate(skeleton.names)}
    owner: dict[str, str] = {}
    out: dict = {}
    for role, value in rig_map.items():
        names = [value] if isinstance(value, str) else list(value)
        for name in names:
            if name not in index:
                raise UsageError(f"rig_map: {label} has no joint {name!r} (given for {role})", params="rig_map")
            if name in owner:
                raise UsageError(f"rig_map: joint {name!r} is given for two roles, {owner[name]} and {role}",
                                 params="rig_map")
            owner[name] = role
        out[role] = tuple(index[n] for n in names) if role in _CHAINS else index[names[0]]
    return out


def _torso(rig: _Rig, given: dict, used: set[int], found: dict) -> list[int]:
    """Find hips and head (into ``found``); the joints strictly between them, bottom to top."""
    feet = [found[f"foot_{s}"] for s in SIDES if found[f"foot_{s}"] is not None]
    hands = [found[f"hand_{s}"] for s in SIDES if found[f"hand_{s}"] is not None]
    head = found["head"]
    hips = given.get("hips")
    if hips is None and feet:
        hips = rig.lca(feet + ([head] if head is not None else hands))
        above = hips
        while hips is not None and not rig.is_hips(hips) and rig.parents[above] >= 0 \
                and len(rig.children[rig.parents[above]]) == 1:  # a hips-named joint straight above (Biped)
            above = rig.parents[above]
            hips = above if rig.is_hips(above) else hips
    elif hips is None:
        named = [j for j in range(len(rig.word)) if rig.is_hips(j) and j not in used]
        hips = min(named, key=lambda j: (rig.depth[j], j)) if named else None
    found["hips"] = hips if hips not in used or "hips" in given else None
    if found["hips"] is None:
        return []
    if head is None:
        arms = rig.lca(hands) if len(hands) == 2 else None
        start, ends = (arms, hands) if arms is not None and arms != found["hips"] else (found["hips"], feet)
        head = rig.top(start, {a for e in ends for a in rig.lineage(e)} | used)
        found["head"] = head if "head" in given or head not in used else None
        if found["head"] is None:
            return []
    path, stop = rig.up_to(found["head"], {found["hips"]})
    if stop is None:
        raise DataError(f"{rig.label}: the head {rig.skeleton.names[found['head']]!r} is not below the hips "
                        f"{rig.skeleton.names[found['hips']]!r}; name both in rig_map", params="rig_map")
    return path[::-1]


def _find(rig: _Rig, given: dict) -> dict:
    """Every role the rig has: role -> joint index (chains: tuple), None where not found."""
    used = {j for v in given.values() for j in (v if isinstance(v, tuple) else (v,))}
    found: dict = {}
    for kind, words in (("hand", _HAND), ("foot", _FOOT)):
        picks = rig.ends(words)
        for s in SIDES:
            role = f"{kind}_{s}"
            found[role] = given[role] if role in given else (picks[s] if picks[s] not in used else None)
    heads = [j for j, w in enumerate(rig.word) if w == "head" and not rig.helper[j] and j not in used]
    found["head"] = given.get("head", min(heads, key=lambda j: (rig.depth[j], j)) if heads else None)
    torso = _torso(rig, given, used, found)
    stop = set(torso) | {found["hips"], found["head"]} - {None}
    attached = []
    for s in SIDES:
        for end, roles, prefer in (("hand", _ARM, _CLAVICLE), ("foot", _LEG, set())):
            j = found[f"{end}_{s}"]
            path, at = rig.up_to(j, stop) if j is not None and found["hips"] is not None else ([], None)
            if at is None:
                path = []  # not below the torso: no limb
            elif end == "hand":
                attached.append(at)
            sided = {r: given[f"{r}_{s}"] for r in roles if f"{r}_{s}" in given}
            for r, b in _assign(rig, rig.bones(path), roles, sided, used, prefer).items():
                found[f"{r}_{s}"] = b
        foot = found[f"foot_{s}"]
        if f"toe_{s}" in given or foot is None:
            found[f"toe_{s}"] = given.get(f"toe_{s}")
            continue
        kids = [c for c in rig.children[foot] if not rig.helper[c] and c not in used]
        toes = [c for c in kids if rig.word[c] in _TOE]
        found[f"toe_{s}"] = toes[0] if toes else (kids[0] if len(kids) == 1 else None)
    if "neck" in given:
        split = next((i for i, t in enumerate(torso) if t in given["neck"]), len(torso))
    elif given.get("spine"):
        split = 1 + max((i for i, t in enumerate(torso) if t in given["spine"]), default=-1)
    else:
        named = [i for i, t in enumerate(torso) if rig.word[t] == "neck" and not rig.helper[t]]
        arms = [torso.index(a) for a in attached if a in torso]
        split = named[0] if named else (max(arms) + 1 if arms else len(torso))
    found["spine"] = given.get("spine", tuple(t for t in torso[:split] if t not in used and not rig.helper[t]))
    found["neck"] = given.get("neck", tuple(t for t in torso[split:] if t not in used and not rig.helper[t]))
    return found


def map_roles(skeleton: Skeleton, rig_map: dict[str, str | list[str]] | None = None,
              label: str = "the skeleton") -> RoleMap:
    """Which joint of ``skeleton`` plays each humanoid role (see the module notes for how it decides).

    ``rig_map``: role -> joint name (``spine``, ``neck``: a list of names, bottom to top), as
    :func:`read_rig_map` reads it; its entries override the automatic mapping for those roles and the rest
    is still found automatically (counting on from a given joint). ``label`` names the skeleton in errors
    (the CLI passes the file name).

    Raises :class:`DataError` (``params="rig_map"``) naming the :data:`REQUIRED` roles it could not find, and
    :class:`UsageError` (``params="rig_map"``) for a ``rig_map`` that names a joint the skeleton lacks, a role
    that does not exist, or one joint for two roles.
    """
    given = _given(skeleton, rig_map, label)
    rig = _Rig(skeleton, label)
    found = _find(rig, given)
    missing = [r for r in REQUIRED if found.get(r) is None]
    if missing:
        raise DataError(f"{label}: found no joint for the humanoid roles {', '.join(missing)}; name them in "
                        f'rig_map (a TOML file of lines role = "JointName", e.g. {missing[0]} = "...")',
                        params="rig_map")
    return RoleMap(names=skeleton.names, hips=found["hips"], spine=found["spine"], neck=found["neck"],
                   head=found["head"], limbs={r: found[r] for r in _LIMBS if found.get(r) is not None})


def read_rig_map(path: str | os.PathLike) -> dict[str, str | list[str]]:
    """A rig map from a TOML file of lines ``role = "JointName"`` (``spine = ["Spine", "Chest"]``, ``neck``: a
    list too), for :func:`map_roles`. A :class:`FormatError` naming the file when it cannot be read, is not
    TOML, or has an entry that is no role of :data:`ROLES` or not joint names."""
    raw = read_regular(path, limits.MAX_SETTINGS_BYTES, "the rig map")  # a regular file: never /dev/zero
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise FormatError(f"not a TOML rig map: {e}", path) from None
    except ValueError as e:  # tomllib's int() of an integer of thousands of digits
        raise FormatError(f"not a usable rig map: {str(e).split(':')[0]}", path) from None
    except RecursionError:  # tomllib nests arrays and inline tables by recursion
        raise FormatError("not a usable rig map: arrays or tables nested too deeply", path) from None
    problem = _entries_problem(data)
    if problem:
        raise FormatError(problem, path)
    return {role: value if isinstance(value, str) else list(value) for role, value in data.items()}
