"""The humanoid role mapper: real fixtures, synthetic rigs of each naming family, rig maps."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA, shared_path

from keyfill.characters.humanoid import REQUIRED, ROLES, RoleMap, map_roles, read_rig_map
from keyfill.cli.common import flag_words
from keyfill.errors import DataError, FormatError, UsageError
from keyfill.io import load
from keyfill.motion import Skeleton

ARM = ("clavicle", "upper_arm", "forearm", "hand")
LEG = ("thigh", "shin", "foot", "toe")
# rest offsets of a T-pose, Y up, facing +Z, in cm, for the left side (x mirrored for the right)
OFFSETS = {"hips": (0, 100, 0), "spine": (0, 10, 0), "neck": (0, 8, 0), "head": (0, 8, 0),
           "clavicle": (5, 3, 0), "upper_arm": (12, 0, 0), "forearm": (28, 0, 0), "hand": (25, 0, 0),
           "thigh": (9, -5, 0), "shin": (0, -42, 0), "foot": (0, -42, 0), "toe": (0, -8, 12)}
Z_UP_FACING_MINUS_Y = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # (x, y, z) -> (x, -z, y)
Z_UP_FACING_PLUS_Y = np.array([[-1, 0, 0], [0, 0, 1], [0, 1, 0]])  # (x, y, z) -> (-x, z, y)


def side_name(template: str, s: str) -> str:
    """``"{Left}Arm"`` -> ``"LeftArm"`` / ``"RightArm"``; also ``{L}``, ``{l}``, ``{left}`` and ``{dup}``
    (nothing on the left, ``.001`` on the right: a Blender duplicate without a side)."""
    left = s == "l"
    return template.format(L="L" if left else "R", l=s, Left="Left" if left else "Right",
                           left="left" if left else "right", dup="" if left else ".001")


def humanoid(layout: dict, insert: dict | None = None, extras=(), pose: str = "T", turn=None,
             up: str = "Y") -> Skeleton:
    """A synthetic humanoid from role -> joint name (limb roles with a side placeholder, spine and neck lists).

    ``insert``: role -> names of joints between that role's joint and its parent (side placeholders allowed),
    which share its offset; ``extras``: ``(name, parent, offset)`` rows added at the end, once per side when
    the name has a placeholder (x mirrored); ``pose`` ``"A"`` turns the arms 45 degrees down; ``turn``: a
    (3, 3) rotation of the whole rest pose (e.g. to Z up, with ``up="Z"``)."""
    insert = insert or {}
    rows: list[tuple[str, str | None, np.ndarray]] = []

    def add(name, parent, offset, role, s="l"):
        above = [side_name(t, s) for t in insert.get(role, ())]
        share = np.asarray(offset, dtype=float) / (len(above) + 1)
        for extra in above:
            if extra not in [r[0] for r in rows]:  # one joint above both legs (Daz's pelvis)
                rows.append((extra, parent, share))
            parent = extra
        rows.append((side_name(name, s), parent, share))
        return side_name(name, s)

    top = add(layout["root"], None, (0, 0, 0), "root") if "root" in layout else None
    hips = add(layout["hips"], top, OFFSETS["hips"], "hips")
    chest = hips
    for name in layout["spine"]:
        chest = add(name, chest, OFFSETS["spine"], "spine")
    above = chest
    for name in layout.get("neck", ()):
        above = add(name, above, OFFSETS["neck"], "neck")
    add(layout["head"], above, OFFSETS["head"], "head")
    down = np.radians(45 if pose == "A" else 0)
    for s in ("l", "r"):
        mirror = np.array([1 if s == "l" else -1, 1, 1])
        parent = layout.get("arm_parent", chest)
        for role in ARM:
            if role in layout:
                off = np.array(OFFSETS[role], dtype=float)
                if role == "upper_arm" and "clavicle" not in layout:
                    off += OFFSETS["clavicle"]
                if role != "clavicle":
                    off = np.array([off[0] * np.cos(down), off[1] - off[0] * np.sin(down), off[2]])
                parent = add(layout[role], parent, off * mirror, role, s)
        parent = layout.get("leg_parent", hips)
        for role in LEG:
            if role in layout:
                parent = add(layout[role], parent, np.array(OFFSETS[role]) * mirror, role, s)
    for name, parent, offset in extras:
        for s in ("l", "r") if "{" in name else ("l",):
            mirror = np.array([1 if s == "l" else -1, 1, 1])
            rows.append((side_name(name, s), side_name(parent, s), np.asarray(offset, dtype=float) * mirror))
    names = [r[0] for r in rows]
    parents = [-1 if r[1] is None else names.index(r[1]) for r in rows]
    offsets = np.array([r[2] for r in rows])
    if turn is not None:
        offsets = offsets @ np.asarray(turn, dtype=float).T
    channels = [("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation") if p < 0
                else ("Zrotation", "Xrotation", "Yrotation") for p in parents]
    return Skeleton(names=tuple(names), parents=parents, offsets=offsets, channels=tuple(channels), up_axis=up)


def expected(layout: dict) -> dict:
    """The roles ``layout`` gives, as :meth:`RoleMap.to_json` writes them."""
    out = {"hips": layout["hips"], "spine": list(layout["spine"]), "neck": list(layout.get("neck", ())),
           "head": layout["head"]}
    for s in ("l", "r"):
        for role in ARM + LEG:
            if role in layout:
                out[f"{role}_{s}"] = side_name(layout[role], s)
    return out


LAFAN1 = {"hips": "Hips", "spine": ["Spine", "Spine1", "Spine2"], "neck": ["Neck"], "head": "Head",
          "clavicle": "{Left}Shoulder", "upper_arm": "{Left}Arm", "forearm": "{Left}ForeArm", "hand": "{Left}Hand",
          "thigh": "{Left}UpLeg", "shin": "{Left}Leg", "foot": "{Left}Foot", "toe": "{Left}Toe"}
UNREAL = {"root": "root", "hips": "pelvis", "spine": [f"spine_0{i}" for i in range(1, 6)],
          "neck": ["neck_01", "neck_02"], "head": "head", "clavicle": "clavicle_{l}", "upper_arm": "upperarm_{l}",
          "forearm": "lowerarm_{l}", "hand": "hand_{l}", "thigh": "thigh_{l}", "shin": "calf_{l}",
          "foot": "foot_{l}", "toe": "ball_{l}"}
UNREAL_EXTRAS = [("upperarm_twist_01_{l}", "upperarm_{l}", (10, 0, 0)),
                 ("upperarm_twist_02_{l}", "upperarm_{l}", (20, 0, 0)),
                 ("lowerarm_twist_01_{l}", "lowerarm_{l}", (14, 0, 0)),
                 ("thigh_twist_01_{l}", "thigh_{l}", (0, -20, 0)),
                 ("calf_twist_01_{l}", "calf_{l}", (0, -20, 0)), ("index_01_{l}", "hand_{l}", (8, 0, 2)),
                 ("index_02_{l}", "index_01_{l}", (3, 0, 0)), ("thumb_01_{l}", "hand_{l}", (3, -1, 3)),
                 ("ik_foot_root", "root", (0, 0, 0)), ("ik_foot_{l}", "ik_foot_root", (9, 11, 0)),
                 ("ik_hand_root", "root", (0, 0, 0)), ("ik_hand_gun", "ik_hand_root", (-60, 140, 0)),
                 ("ik_hand_{l}", "ik_hand_gun", (120, 0, 0))]
SMPL = {"hips": "pelvis", "spine": ["spine1", "spine2", "spine3"], "neck": ["neck"], "head": "head",
        "clavicle": "{L}_Collar", "upper_arm": "{L}_Shoulder", "forearm": "{L}_Elbow", "hand": "{L}_Wrist",
        "thigh": "{L}_Hip", "shin": "{L}_Knee", "foot": "{L}_Ankle", "toe": "{L}_Foot"}
SMPLX = {**SMPL, "clavicle": "{left}_collar", "upper_arm": "{left}_shoulder", "forearm": "{left}_elbow",
         "hand": "{left}_wrist", "thigh": "{left}_hip", "shin": "{left}_knee", "foot": "{left}_ankle",
         "toe": "{left}_foot"}
RIGIFY = {"hips": "DEF-spine", "spine": ["DEF-spine.001", "DEF-spine.002", "DEF-spine.003"],
          "neck": ["DEF-spine.004", "DEF-spine.005"], "head": "DEF-spine.006", "clavicle": "DEF-shoulder.{L}",
          "upper_arm": "DEF-upper_arm.{L}", "forearm": "DEF-forearm.{L}", "hand": "DEF-hand.{L}",
          "thigh": "DEF-thigh.{L}", "shin": "DEF-shin.{L}", "foot": "DEF-foot.{L}", "toe": "DEF-toe.{L}"}
RIGIFY_SEGMENTS = {"forearm": ["DEF-upper_arm.{L}.001"], "hand": ["DEF-forearm.{L}.001"],
                   "shin": ["DEF-thigh.{L}.001"], "foot": ["DEF-shin.{L}.001"]}
RIGIFY_EXTRAS = [("DEF-pelvis.{L}", "DEF-spine", (8, -2, 4)), ("DEF-breast.{L}", "DEF-spine.003", (6, 0, 6)),
                 ("DEF-f_index.01.{L}", "DEF-hand.{L}", (8, 0, 2)), ("DEF-jaw", "DEF-spine.006", (0, -2, 5)),
                 ("DEF-eye.{L}", "DEF-spine.006", (3, 4, 6))]
BLENDER = {"hips": "hips", "spine": ["spine", "chest"], "neck": ["neck"], "head": "head",
           "clavicle": "shoulder.{L}", "upper_arm": "upper_arm.{L}", "forearm": "forearm.{L}", "hand": "hand.{L}",
           "thigh": "thigh.{L}", "shin": "shin.{L}", "foot": "foot.{L}", "toe": "toe.{L}"}
JOINT_NAMED = {"hips": "Hips", "spine": ["Chest"], "neck": ["Neck"], "head": "Head", "clavicle": "{Left}Collar",
               "upper_arm": "{Left}Shoulder", "forearm": "{Left}Elbow", "hand": "{Left}Wrist", "thigh": "{Left}Hip",
               "shin": "{Left}Knee", "foot": "{Left}Ankle"}
NO_COLLAR = {k: v for k, v in JOINT_NAMED.items() if k != "clavicle"}
VRM = {"root": "Root", "hips": "J_Bip_C_Hips", "spine": ["J_Bip_C_Spine", "J_Bip_C_Chest", "J_Bip_C_UpperChest"],
       "neck": ["J_Bip_C_Neck"], "head": "J_Bip_C_Head", "clavicle": "J_Bip_{L}_Shoulder",
       "upper_arm": "J_Bip_{L}_UpperArm", "forearm": "J_Bip_{L}_LowerArm", "hand": "J_Bip_{L}_Hand",
       "thigh": "J_Bip_{L}_UpperLeg", "shin": "J_Bip_{L}_LowerLeg", "foot": "J_Bip_{L}_Foot",
       "toe": "J_Bip_{L}_ToeBase"}
DAZ = {"hips": "hip", "spine": ["abdomenLower", "abdomenUpper", "chestLower", "chestUpper"],
       "neck": ["neckLower", "neckUpper"], "head": "head", "clavicle": "{l}Collar", "upper_arm": "{l}ShldrBend",
       "forearm": "{l}ForearmBend", "hand": "{l}Hand", "thigh": "{l}ThighBend", "shin": "{l}Shin", "foot": "{l}Foot",
       "toe": "{l}Toe"}
DAZ_TWISTS = {"thigh": ["pelvis"], "shin": ["{l}ThighTwist"], "forearm": ["{l}ShldrTwist"],
              "hand": ["{l}ForearmTwist"]}
BIPED = {"root": "Bip01", "hips": "Bip01_Pelvis", "spine": ["Bip01_Spine", "Bip01_Spine1", "Bip01_Spine2"],
         "neck": ["Bip01_Neck"], "head": "Bip01_Head", "clavicle": "Bip01_{L}_Clavicle",
         "upper_arm": "Bip01_{L}_UpperArm", "forearm": "Bip01_{L}_Forearm", "hand": "Bip01_{L}_Hand",
         "thigh": "Bip01_{L}_Thigh", "shin": "Bip01_{L}_Calf",
         "foot": "Bip01_{L}_Foot", "toe": "Bip01_{L}_Toe0", "leg_parent": "Bip01_Spine", "arm_parent": "Bip01_Neck"}
ASF = {"hips": "hip", "spine": ["lowerback", "upperback", "thorax"], "neck": ["lowerneck", "upperneck"],
       "head": "head", "clavicle": "{l}clavicle", "upper_arm": "{l}humerus", "forearm": "{l}radius",
       "hand": "{l}wrist", "thigh": "{l}femur", "shin": "{l}tibia", "foot": "{l}foot", "toe": "{l}toes"}
ASF_EXTRAS = [("{l}hand", "{l}wrist", (6, 0, 0)), ("{l}fingers", "{l}hand", (4, 0, 0)),
              ("{l}thumb", "{l}hand", (2, 0, 3))]
UNSIDED = {"hips": "hips", "spine": ["spine", "chest"], "neck": ["neck"], "head": "head",
           "clavicle": "shoulder{dup}", "upper_arm": "upper_arm{dup}", "forearm": "forearm{dup}", "hand": "hand{dup}",
           "thigh": "thigh{dup}", "shin": "shin{dup}", "foot": "foot{dup}", "toe": "toe{dup}"}

FAMILIES = {
    "lafan1": {"layout": LAFAN1},
    "lafan1-a-pose": {"layout": LAFAN1, "pose": "A"},
    "unreal-twist-bones": {"layout": UNREAL, "extras": UNREAL_EXTRAS},
    "unreal-twists-in-the-chain": {"layout": UNREAL, "insert": {"forearm": ["upperarm_twist_01_{l}"],
                                                              "hand": ["lowerarm_twist_01_{l}"]}},
    "smpl": {"layout": SMPL, "extras": [("{L}_Hand", "{L}_Wrist", (8, 0, 0))]},
    "smplx-lowercase": {"layout": SMPLX, "extras": [("{left}_index1", "{left}_wrist", (8, 0, 1))]},
    "rigify": {"layout": RIGIFY, "insert": RIGIFY_SEGMENTS, "extras": RIGIFY_EXTRAS},
    "blender-z-up": {"layout": BLENDER, "turn": Z_UP_FACING_MINUS_Y, "up": "Z"},
    "joint-named": {"layout": JOINT_NAMED},
    "joint-named-a-pose": {"layout": JOINT_NAMED, "pose": "A"},
    "joint-named-no-collar": {"layout": NO_COLLAR},
    "vrm": {"layout": VRM},
    "cmu-asf": {"layout": ASF, "insert": {"thigh": ["{l}hipjoint"]}, "extras": ASF_EXTRAS},
    "daz-genesis": {"layout": DAZ, "insert": DAZ_TWISTS},
    "3dsmax-biped": {"layout": BIPED, "extras": [("Bip01_{L}_Toe0Nub", "Bip01_{L}_Toe0", (0, 0, 4)),
                                               ("Bip01_HeadNub", "Bip01_Head", (0, 15, 0))]},
}


def family(name: str) -> Skeleton:
    return humanoid(**FAMILIES[name])


MIXAMO = {"hips": "Hips", "spine": ["Spine", "Spine1", "Spine2"], "neck": ["Neck"], "head": "Head",
          **{f"{r}_{s}": f"{side}{w}" for s, side in (("l", "Left"), ("r", "Right")) for r, w in (
              ("clavicle", "Shoulder"), ("upper_arm", "Arm"), ("forearm", "ForeArm"), ("hand", "Hand"),
              ("thigh", "UpLeg"), ("shin", "Leg"), ("foot", "Foot"), ("toe", "ToeBase"))}}
CMU = {**MIXAMO, "spine": ["LowerBack", "Spine", "Spine1"], "neck": ["Neck", "Neck1"]}
BANDAI = {"hips": "Hips", "spine": ["Spine", "Chest"], "neck": ["Neck"], "head": "Head",
          **{f"{r}_{s}": f"{w}_{s.upper()}" for s in ("l", "r") for r, w in (
              ("clavicle", "Shoulder"), ("upper_arm", "UpperArm"), ("forearm", "LowerArm"), ("hand", "Hand"),
              ("thigh", "UpperLeg"), ("shin", "LowerLeg"), ("foot", "Foot"), ("toe", "Toes"))}}


def prefixed(roles: dict, prefix: str) -> dict:
    return {k: [prefix + n for n in v] if isinstance(v, list) else prefix + v for k, v in roles.items()}


def bandai_skeleton() -> Skeleton:
    return load(shared_path("bvh_fixtures", "dataset-1_walk_normal_002.bvh")).skeleton


def test_mixamo_fixture():
    sk = load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton
    m = map_roles(sk)
    assert sk.num_joints == 55
    assert m.to_json() == prefixed(MIXAMO, "mixamorig:")
    assert (m.hips, m.spine, m.neck, m.head) == (0, (1, 2, 3), (4,), 5)
    assert m.limbs["hand_l"] == 12 and m.limbs["toe_r"] == 50


def test_cmu_fixture():
    sk = load(DATA / "cmu_02_03_cgspeed_first4frames.bvh").skeleton
    m = map_roles(sk)
    assert sk.num_joints == 31
    assert m.to_json() == CMU
    unmapped = set(sk.names) - {sk.names[j] for j in (m.hips, m.head, *m.spine, *m.neck, *m.limbs.values())}
    assert unmapped == {"LHipJoint", "RHipJoint", "LeftFingerBase", "RightFingerBase", "LeftHandIndex1",
                        "RightHandIndex1", "LThumb", "RThumb"}


def test_bandai_fixture():
    sk = bandai_skeleton()
    m = map_roles(sk)
    assert m.to_json() == BANDAI
    assert sk.names[0] == "joint_Root" and m.hips == 1


def test_bandai_zero_pose_has_no_body_geometry():
    """The Bandai rest pose lies along X: feet at the hips' height, the head beside the hips, a leg pointing
    up the other's side. A mapper leaning on "feet are lowest, head is highest" would fail; ours does not."""
    sk = bandai_skeleton()
    w = sk.rest_world_positions()
    i = {n: k for k, n in enumerate(sk.names)}
    up = w[:, 1]
    assert abs(up[i["Foot_L"]] - up[i["Hips"]]) < 10 and abs(up[i["Head"]] - up[i["Hips"]]) < 1
    assert up[i["Foot_R"]] > up[i["Hips"]] > up[i["Foot_L"]]
    assert map_roles(sk).to_json() == BANDAI


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mapping_ignores_rest_geometry(seed):
    """Random rest offsets (seeded) change nothing where names give the sides: the hierarchy decides."""
    rng = np.random.default_rng(seed)
    for sk in (load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton, family("rigify"), family("smpl"),
               family("joint-named"), family("unreal-twist-bones")):
        scrambled = Skeleton(names=sk.names, parents=sk.parents, offsets=rng.normal(0, 20, sk.offsets.shape),
                             channels=sk.channels)
        assert map_roles(scrambled).to_json() == map_roles(sk).to_json()


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_naming_families(name):
    m = map_roles(family(name), label=name)
    assert m.to_json() == expected(FAMILIES[name]["layout"])
    assert all(m.joint(r) is not None for r in REQUIRED)


def test_same_word_decided_by_hierarchy():
    lafan, joints, smpl = (map_roles(family(f)).to_json() for f in ("lafan1", "joint-named", "smpl"))
    assert lafan["clavicle_l"] == "LeftShoulder" and lafan["upper_arm_l"] == "LeftArm"
    assert joints["upper_arm_l"] == "LeftShoulder" and joints["clavicle_l"] == "LeftCollar"
    assert "clavicle_l" not in map_roles(family("joint-named-no-collar")).to_json()
    assert lafan["shin_l"] == "LeftLeg"
    assert smpl["foot_l"] == "L_Ankle" and smpl["toe_l"] == "L_Foot" and smpl["hand_l"] == "L_Wrist"


def test_twist_and_ik_bones_are_not_mapped():
    for name in ("unreal-twist-bones", "unreal-twists-in-the-chain", "daz-genesis"):
        m = map_roles(family(name))
        mapped = [m.names[j] for j in (*m.spine, *m.neck, *m.limbs.values())]
        assert not any("twist" in n.lower() or "ik_" in n for n in mapped), name


def with_joint(sk: Skeleton, template: str, child: str, at_parent: bool = True) -> Skeleton:
    """``sk`` with a joint (per side for a side template) between ``child`` and its parent: at the parent
    (zero offset) or, with ``at_parent=False``, halfway."""
    for s in ("l", "r") if "{" in template else ("l",):
        name, below = side_name(template, s), side_name(child, s)
        c = sk.names.index(below)
        names = list(sk.names[:c]) + [name] + list(sk.names[c:])
        parents = [int(p) for p in sk.parents[:c + 1]] + [int(p) + (p >= c) for p in sk.parents[c:]]
        parents[c + 1] = c  # the child hangs from the new joint
        half = sk.offsets[c] * (0 if at_parent else 0.5)
        offsets = np.concatenate([sk.offsets[:c], [half], [sk.offsets[c] - half], sk.offsets[c + 1:]])
        sk = Skeleton(names=names, parents=parents, offsets=offsets,
                      channels=list(sk.channels[:c]) + [sk.channels[c]] + list(sk.channels[c:]), up_axis=sk.up_axis)
    return sk


@pytest.mark.parametrize("template, child, at_parent, changed", [
    ("{Left}ArmRoll", "{Left}ForeArm", True, {}),  # a roll helper sitting on the upper arm
    ("{Left}ArmRoll", "{Left}ForeArm", False, {}),  # halfway down the upper arm
    ("{Left}Arm1", "{Left}ForeArm", True, {}),  # a segment of the upper arm, on it
    ("{Left}ForeArm.001", "{Left}Hand", False, {}),  # a segment of the forearm, halfway
    # an unnamed joint on the upper arm: its bone, not the zero-length one above it, is the upper arm
    ("{Left}ArmX", "{Left}ForeArm", True, {"upper_arm_l": "LeftArmX", "upper_arm_r": "RightArmX"}),
    ("{Left}UpLegTwist", "{Left}Leg", False, {}),
    ("SpineRoll", "Spine2", False, {}),  # a helper in the torso: not part of the spine
])
def test_helpers_segments_and_zero_length_joints(template, child, at_parent, changed):
    sk = with_joint(family("lafan1"), template, child, at_parent)
    assert sk.num_joints == family("lafan1").num_joints + (2 if "{" in template else 1)
    assert map_roles(sk).to_json() == {**expected(LAFAN1), **changed}


def test_joint_order_does_not_matter():
    """SMPL lists its joints breadth first (pelvis, L_Hip, R_Hip, spine1, L_Knee, ...)."""
    sk = family("smpl")
    order = sorted(range(sk.num_joints), key=lambda j: (len(_lineage(sk, j)), j))
    new = {old: k for k, old in enumerate(order)}
    bfs = Skeleton(names=[sk.names[j] for j in order], parents=[new.get(int(sk.parents[j]), -1) for j in order],
                   offsets=sk.offsets[order], channels=[sk.channels[j] for j in order])
    assert bfs.names[:4] == ("pelvis", "spine1", "L_Hip", "R_Hip")
    assert map_roles(bfs).to_json() == expected(SMPL)


def _lineage(sk: Skeleton, j: int) -> list[int]:
    out = [j]
    while sk.parents[out[-1]] >= 0:
        out.append(int(sk.parents[out[-1]]))
    return out


@pytest.mark.parametrize("pose, turn, up", [("T", None, "Y"), ("A", None, "Y"), ("T", Z_UP_FACING_MINUS_Y, "Z"),
                                            ("A", Z_UP_FACING_PLUS_Y, "Z")])
def test_sides_from_the_rest_pose_where_names_are_silent(pose, turn, up):
    """``hand`` / ``hand.001``: the character's left is up x the way the feet point, Y or Z up, either facing."""
    sk = humanoid(UNSIDED, pose=pose, turn=turn, up=up)
    m = map_roles(sk)
    assert m.to_json() == expected(UNSIDED)
    # the mirror image (the character's lateral axis is X in each case): the other joint is on the left now
    mirrored = Skeleton(names=sk.names, parents=sk.parents, offsets=sk.offsets * [-1, 1, 1], channels=sk.channels,
                        up_axis=up)
    assert map_roles(mirrored).to_json()["hand_l"] == "hand.001"


@pytest.mark.parametrize("missing, roles", [
    (("thigh", "shin", "foot", "toe"), "thigh_l, shin_l, foot_l, thigh_r, shin_r, foot_r"),
    (("clavicle", "upper_arm", "forearm", "hand"), "upper_arm_l, forearm_l, hand_l, upper_arm_r, forearm_r, hand_r"),
])
def test_missing_limbs_fail_naming_the_roles(missing, roles):
    sk = humanoid({k: v for k, v in LAFAN1.items() if k not in missing})
    with pytest.raises(DataError) as err:
        map_roles(sk, label="legless.bvh")
    message = str(err.value)
    assert message.startswith("legless.bvh: ") and f"roles {roles};" in message and "\n" not in message
    assert err.value.params == ("rig_map",)
    assert "name them in --rig-map (a TOML file" in flag_words(message, err.value.params)


def test_rig_map_gives_what_names_do_not():
    layout = {**JOINT_NAMED, "hand": "{Left}Mitt"}
    sk = humanoid(layout)
    with pytest.raises(DataError, match="upper_arm_l, forearm_l, hand_l, upper_arm_r, forearm_r, hand_r;"):
        map_roles(sk)
    m = map_roles(sk, {"hand_l": "LeftMitt", "hand_r": "RightMitt"})
    assert m.to_json() == expected(layout)  # the arms counted on from the given hands


def test_rig_map_overrides_and_the_rest_is_automatic():
    sk = load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton
    auto = map_roles(sk).to_json()
    m = map_roles(sk, {"spine": ["mixamorig:Spine", "mixamorig:Spine1"],
                       "upper_arm_l": "mixamorig:LeftShoulder"}).to_json()
    assert m["spine"] == ["mixamorig:Spine", "mixamorig:Spine1"]
    assert m["neck"] == ["mixamorig:Spine2", "mixamorig:Neck"]  # the torso above the given spine
    # counted on from the given upper arm: the forearm below it, no clavicle above it (the torso is next)
    assert (m["upper_arm_l"], m["forearm_l"], m["hand_l"]) == (
        "mixamorig:LeftShoulder", "mixamorig:LeftForeArm", "mixamorig:LeftHand")
    assert "clavicle_l" not in m
    rest = [k for k in auto if k not in ("spine", "neck", "clavicle_l", "upper_arm_l")]
    assert {k: m[k] for k in rest} == {k: auto[k] for k in rest}


def test_rig_map_with_the_head_outside_the_hips():
    with pytest.raises(DataError) as err:
        map_roles(family("lafan1"), {"hips": "LeftUpLeg"}, label="walk.bvh")
    assert str(err.value) == ("walk.bvh: the head 'Head' is not below the hips 'LeftUpLeg'; name both in rig_map")
    assert err.value.params == ("rig_map",)


@pytest.mark.parametrize("name", ["lafan1", "rigify", "joint-named-no-collar", "daz-genesis", "3dsmax-biped"])
def test_to_json_is_a_rig_map_that_gives_the_same_roles(name):
    sk = family(name)
    m = map_roles(sk)
    assert map_roles(sk, m.to_json()) == m


@pytest.mark.parametrize("rig_map, words", [
    ({"hand_l": "LeftPaw"}, ["has no joint 'LeftPaw'", "hand_l"]),
    ({"tail": "Hips"}, ["'tail' is no humanoid role", "hips, spine, neck, head"]),
    ({"hand_l": "LeftHand", "forearm_l": "LeftHand"},
     ["joint 'LeftHand' is given for two roles, hand_l and forearm_l"]),
    ({"spine": ["Spine", "Spine1"], "neck": ["Spine1"]}, ["joint 'Spine1' is given for two roles, spine and neck"]),
    ({"hips": ["Hips"]}, ["hips must be one joint name"]),
    ({"spine": 3}, ["spine must be a list of joint names"]),
])
def test_bad_rig_maps(rig_map, words):
    with pytest.raises(UsageError) as err:
        map_roles(family("lafan1"), rig_map, label="walk.bvh")
    message = str(err.value)
    assert all(w in message for w in words) and "\n" not in message
    assert err.value.params == ("rig_map",) and message.startswith("rig_map: ")
    assert flag_words(message, err.value.params).startswith("--rig-map: ")


def test_read_rig_map(tmp_path):
    good = tmp_path / "rig.toml"
    good.write_text('# my character\nhips = "Hips"\nspine = ["Spine", "Spine1", "Spine2"]\nhand_l = "LeftHand"\n')
    rig_map = read_rig_map(good)
    assert rig_map == {"hips": "Hips", "spine": ["Spine", "Spine1", "Spine2"], "hand_l": "LeftHand"}
    assert map_roles(family("lafan1"), rig_map).to_json() == expected(LAFAN1)


@pytest.mark.parametrize("text, words", [
    ('hips = "Hips"\nspine = ["Spine",\n', "not a TOML rig map"),
    ("hips = 3\n", "hips must be one joint name, not 3"),
    ('[hand]\nl = "LeftHand"\n', "'hand' is no humanoid role"),
    (b"hips = \"H\xffips\"\n", "not a TOML rig map"),
])
def test_read_rig_map_bad_files(tmp_path, text, words):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(FormatError) as err:
        read_rig_map(bad)
    assert str(err.value).startswith(f"{bad}: ") and words in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(FormatError, match="cannot read the rig map"):
        read_rig_map(tmp_path / "absent.toml")


def test_describe_and_single_roles():
    m = map_roles(family("joint-named"))
    lines = m.describe()
    assert len(lines) == len(ROLES) and lines[:4] == ["hips: Hips", "spine: Chest", "neck: Neck", "head: Head"]
    assert "clavicle_l: LeftCollar" in lines and "toe_l: (none)" in lines
    names = m.names
    assert (names[m.joint("spine_top")], names[m.joint("spine_bottom")], names[m.joint("neck_top")]) == (
        "Chest", "Chest", "Neck")
    assert m.joint("toe_l") is None and names[m.joint("hand_r")] == "RightWrist"
    assert map_roles(humanoid({**LAFAN1, "neck": []})).joint("neck_top") is None
    with pytest.raises(UsageError, match="no single-joint humanoid role 'spine'"):
        m.joint("spine")


def test_role_map_checks_its_joints():
    names = ("Hips", "Spine", "Head")
    with pytest.raises(DataError, match="joint 'Spine' plays two roles, spine and head"):
        RoleMap(names=names, hips=0, spine=(1,), neck=(), head=1, limbs={})
    with pytest.raises(DataError, match="no limb role 'tail_l'"):
        RoleMap(names=names, hips=0, spine=(1,), neck=(), head=2, limbs={"tail_l": 1})
    with pytest.raises(DataError, match="outside"):
        RoleMap(names=names, hips=0, spine=(1,), neck=(), head=3, limbs={})


@pytest.mark.parametrize("prefix", ["mixamorig12:", "Armature|mixamorig:", "char:mixamorig1:"])
def test_any_namespace_prefix(prefix):
    sk = load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton
    renamed = Skeleton(names=[prefix + n.split(":")[-1] for n in sk.names], parents=sk.parents, offsets=sk.offsets,
                       channels=sk.channels)
    assert map_roles(renamed).to_json() == prefixed(MIXAMO, prefix)
