"""Left-right mirroring through the humanoid roles, where joint names do not pair (issue 30)."""

from __future__ import annotations

import numpy as np
from test_humanoid_roles import UNSIDED, family, humanoid

from keyfill import rotations as R
from keyfill.characters.humanoid import map_roles
from keyfill.kinematics import fk
from keyfill.learn import mirror as M


def walk(skeleton, frames: int = 60, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A seeded walk on a humanoid: legs and arms swing in antiphase, every other joint sways a little,
    the hips move forward along +Z and drift to the character's left, so the two feet's paths differ."""
    roles = map_roles(skeleton)
    rng = np.random.default_rng(seed)
    J, t = skeleton.num_joints, np.arange(frames) / 30.0
    phase = 2 * np.pi * 1.8 * t
    euler = rng.uniform(0.02, 0.15, (J, 3)) * np.sin(phase[:, None, None] + rng.uniform(0, 6.3, (J, 3)))
    for side, sign in (("l", 1.0), ("r", -1.0)):
        euler[:, roles.limbs[f"thigh_{side}"], 1] = 0.5 * sign * np.sin(phase)
        euler[:, roles.limbs[f"shin_{side}"], 1] = 0.4 * np.maximum(-sign * np.sin(phase), 0)
        euler[:, roles.limbs[f"upper_arm_{side}"], 1] = -0.3 * sign * np.sin(phase)
    root = np.stack([15 * t, 100 + 2 * np.sin(2 * phase), 110 * t], -1)
    return R.euler_to_quat(euler, "ZXY"), root


def world(skeleton, quats, root):
    pos = np.broadcast_to(skeleton.offsets, quats.shape[:-1] + (3,)).copy()
    pos[:, 0] = root
    return fk(quats, pos, skeleton.parents)[1]


def test_roles_pair_what_names_cannot():
    sk = family("cmu-asf")  # lfemur / rfemur, with an lhipjoint above the thigh and fingers below the hand
    assert M.mirror_pairs(sk.names) is None
    perm = M.role_pairs(sk)
    pairs = {sk.names[i]: sk.names[p] for i, p in enumerate(perm)}
    # limb roles, a joint between a limb and the torso (its parent), joints below a hand (its children)
    for left in ("lfemur", "lfoot", "lclavicle", "lhipjoint", "lhand", "lfingers", "lthumb"):
        assert pairs[left] == "r" + left[1:] and pairs["r" + left[1:]] == left
    for centre in ("hip", "lowerback", "thorax", "upperneck", "head"):
        assert pairs[centre] == centre
    assert M.role_pairs(humanoid({"hips": "Hips", "spine": ["Spine"], "head": "Head"})) is None  # no limbs


def test_a_limb_role_on_one_side_only_has_no_mirror():
    sk = humanoid({**UNSIDED})
    names = list(sk.names)
    # drop the right toe: the left toe has no partner
    keep = [i for i, n in enumerate(names) if n != "toe.001"]
    lost = sk.replace(names=tuple(names[i] for i in keep), parents=[keep.index(sk.parents[i]) if sk.parents[i] >= 0
                      else -1 for i in keep], offsets=sk.offsets[keep], channels=tuple(sk.channels[i] for i in keep))
    assert M.role_pairs(sk) is not None and M.role_pairs(lost) is None


def test_mirrored_walk_swaps_the_feet_and_twice_is_the_identity():
    for sk in (family("cmu-asf"), humanoid(UNSIDED)):  # sides by glued letters; no sides in the names at all
        q, root = walk(sk)
        mirror = M.find_mirror(sk, q)
        assert mirror is not None, sk.names
        mq, mroot = mirror(q, root)
        p, mp = world(sk, q, root), world(sk, mq, mroot)
        roles = map_roles(sk)
        for a, b in (("foot_l", "foot_r"), ("foot_r", "foot_l"), ("toe_l", "toe_r"), ("hand_l", "hand_r")):
            # the left foot of the mirror walks where the right foot walked, reflected across the lateral axis
            np.testing.assert_allclose(mp[:, roles.limbs[a]], p[:, roles.limbs[b]] * [-1, 1, 1], atol=1e-9)
        assert np.abs(p[:, roles.limbs["foot_l"]] - p[:, roles.limbs["foot_r"]] * [-1, 1, 1]).max() > 1.0
        np.testing.assert_allclose(mp[:, mirror.perm], p * [-1, 1, 1], atol=1e-9)  # every joint
        qq, rr = mirror(mq, mroot)
        np.testing.assert_allclose(np.abs(np.sum(qq * q, -1)), 1.0, atol=1e-12)
        np.testing.assert_allclose(rr, root)
