"""A small synthetic character for the tangent-editing tests (no shared data needed).

``character()`` is a 21-joint biped in centimetres (Y up, ZXY Euler channels
like the Bandai rig) whose upper body waves while its lower body stands
still, so both feet are true contacts for the whole clip. It is built from
sinusoids with fixed phases: deterministic, no randomness.
"""

from __future__ import annotations

import numpy as np

from keyfill import rotations as R
from keyfill.motion import Keys, Motion, Skeleton

ROT = ("Zrotation", "Xrotation", "Yrotation")
ROOT = ("Xposition", "Yposition", "Zposition") + ROT

#: name, parent, offset (cm)
JOINTS = [
    ("Hips", None, (0, 92, 0)),
    ("Spine", "Hips", (0, 10, 0)),
    ("Chest", "Spine", (0, 20, 0)),
    ("Neck", "Chest", (0, 22, 0)),
    ("Head", "Neck", (0, 10, 0)),
    ("Shoulder_L", "Chest", (4, 18, 0)),
    ("UpperArm_L", "Shoulder_L", (12, 0, 0)),
    ("LowerArm_L", "UpperArm_L", (28, 0, 0)),
    ("Hand_L", "LowerArm_L", (25, 0, 0)),
    ("Shoulder_R", "Chest", (-4, 18, 0)),
    ("UpperArm_R", "Shoulder_R", (-12, 0, 0)),
    ("LowerArm_R", "UpperArm_R", (-28, 0, 0)),
    ("Hand_R", "LowerArm_R", (-25, 0, 0)),
    ("UpperLeg_L", "Hips", (9, -4, 0)),
    ("LowerLeg_L", "UpperLeg_L", (0, -42, 0)),
    ("Foot_L", "LowerLeg_L", (0, -41, 0)),
    ("Toes_L", "Foot_L", (0, -5, 13)),
    ("UpperLeg_R", "Hips", (-9, -4, 0)),
    ("LowerLeg_R", "UpperLeg_R", (0, -42, 0)),
    ("Foot_R", "LowerLeg_R", (0, -41, 0)),
    ("Toes_R", "Foot_R", (0, -5, 13)),
]
KEYS = (0, 10, 20, 30, 40)

#: joint -> (static angles, amplitudes, phases) in degrees, ZXY order
_WAVE = {
    "Spine": ((0, 5, 0), (4, 6, 8), (0.0, 1.0, 2.0)),
    "Chest": ((0, 3, 0), (5, 4, 10), (0.5, 1.5, 2.5)),
    "Neck": ((0, 0, 0), (6, 8, 12), (1.0, 2.0, 0.3)),
    "Head": ((0, -5, 0), (5, 6, 10), (2.0, 0.4, 1.1)),
    "Shoulder_L": ((5, 0, 0), (4, 3, 5), (0.2, 0.9, 1.7)),
    "UpperArm_L": ((-60, 10, 20), (25, 15, 20), (0.0, 1.2, 2.2)),
    "LowerArm_L": ((0, 0, 40), (6, 5, 30), (0.7, 1.9, 0.1)),
    "Hand_L": ((0, 0, 0), (10, 8, 12), (1.3, 0.5, 2.6)),
    "Shoulder_R": ((-5, 0, 0), (4, 3, 5), (1.2, 0.1, 0.8)),
    "UpperArm_R": ((60, 10, -20), (25, 15, 20), (2.0, 0.3, 1.4)),
    "LowerArm_R": ((0, 0, -40), (6, 5, 30), (1.7, 2.9, 0.6)),
    "Hand_R": ((0, 0, 0), (10, 8, 12), (0.3, 1.5, 2.1)),
    "UpperLeg_L": ((0, -10, 0), (0, 0, 0), (0, 0, 0)),
    "LowerLeg_L": ((0, 15, 0), (0, 0, 0), (0, 0, 0)),
    "Foot_L": ((0, -5, 0), (0, 0, 0), (0, 0, 0)),
    "UpperLeg_R": ((0, -10, 0), (0, 0, 0), (0, 0, 0)),
    "LowerLeg_R": ((0, 15, 0), (0, 0, 0), (0, 0, 0)),
    "Foot_R": ((0, -5, 0), (0, 0, 0), (0, 0, 0)),
}


def skeleton() -> Skeleton:
    names = [j[0] for j in JOINTS]
    parents = [-1 if p is None else names.index(p) for _, p, _ in JOINTS]
    return Skeleton(
        names=tuple(names),
        parents=np.array(parents),
        offsets=np.array([o for _, _, o in JOINTS], dtype=np.float64),
        channels=tuple(ROOT if p is None else ROT for _, p, _ in JOINTS),
        end_sites=((4, np.array([0.0, 16.0, 0.0])), (8, np.array([8.0, 0.0, 0.0])), (12, np.array([-8.0, 0.0, 0.0]))),
        meters_per_unit=0.01,
        up_axis="Y",
    )


def character(num_frames: int = 41) -> Motion:
    """The waving biped, ``num_frames`` frames at 30 fps, keys at :data:`KEYS`."""
    sk = skeleton()
    t = np.arange(num_frames) / 30.0
    angles = np.zeros((num_frames, sk.num_joints, 3))
    for name, (static, amp, phase) in _WAVE.items():
        j = sk.index(name)
        for k in range(3):
            angles[:, j, k] = np.radians(static[k] + amp[k] * np.sin(2 * np.pi * 0.7 * t + phase[k]))
    rot = R.euler_to_quat(angles, "ZXY")
    pos = np.broadcast_to(sk.offsets, (num_frames, sk.num_joints, 3)).copy()
    keys = Keys(np.array([k for k in KEYS if k < num_frames]))
    return Motion(sk, 30.0, rot, pos, keys=keys)


def test_character_feet_are_still_and_hands_move():
    m = character()
    wp = m.world_positions()
    for toe in ("Toes_L", "Toes_R"):
        j = m.skeleton.index(toe)
        assert np.ptp(wp[:, j], axis=0).max() < 1e-9
    hand = m.skeleton.index("Hand_L")
    assert np.ptp(wp[:, hand], axis=0).max() > 10.0
