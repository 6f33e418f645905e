"""Foot contacts and foot locking (keyfill.characters.feet) on hand-made steps of a small biped, on a Z-up
24-unit-tall copy of it, on the Mixamo fixture and on the Bandai rig; the lamp has no legs."""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import BVH_FIXTURES, DATA

from keyfill import rotations as R
from keyfill.characters.feet import (
    FootSettings,
    contact_joints,
    contacts,
    foot_chains,
    ground_height,
    label_contacts,
    lock_feet,
)
from keyfill.characters.lamp import lamp_skeleton
from keyfill.characters.retarget import make_rig
from keyfill.errors import DataError, UsageError
from keyfill.io import load
from keyfill.kinematics import fk, two_bone_ik
from keyfill.motion import Keys, Motion, Skeleton

FPS = 30.0
NAMES = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
         "RightToeBase", "Spine", "Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm",
         "RightHand")
PARENTS = (-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 9, 12, 13, 9, 15, 16)
OFFSETS = np.array([[0, 1.0, 0], [0.1, -0.05, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.05, 0.12],
                    [-0.1, -0.05, 0], [0, -0.45, 0], [0, -0.42, 0], [0, -0.05, 0.12], [0, 0.2, 0], [0, 0.3, 0],
                    [0, 0.1, 0], [0.18, 0.25, 0], [0.28, 0, 0], [0.25, 0, 0], [-0.18, 0.25, 0], [-0.28, 0, 0],
                    [-0.25, 0, 0]])
ROOT = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
JOINT = ("Zrotation", "Xrotation", "Yrotation")


def biped() -> Skeleton:
    """A small Y-up biped in meters: hips 1 m up, thigh 0.45, shin 0.42, ankle 8 cm, toe 3 cm above the ground."""
    ends = ((4, np.array([0, 0, 0.05])), (8, np.array([0, 0, 0.05])), (11, np.array([0, 0.15, 0])),
            (14, np.array([0.08, 0, 0])), (17, np.array([-0.08, 0, 0])))
    return Skeleton(NAMES, np.array(PARENTS), OFFSETS, (ROOT,) + (JOINT,) * 17, ends, meters_per_unit=1.0)


def author(sk: Skeleton, hips: np.ndarray, ankles: dict[str, np.ndarray]) -> Motion:
    """A motion whose hips follow ``hips (F, 3)`` (no turn) and whose ankles go to ``ankles[side] (F, 3)`` by
    two-bone IK (knees forward); the feet stay level."""
    F = len(hips)
    rot = np.tile([1.0, 0, 0, 0], (F, sk.num_joints, 1))
    pos = np.broadcast_to(sk.offsets, (F, sk.num_joints, 3)).copy()
    pos[:, 0] = hips
    for side, (thigh, shin, foot) in (("l", (1, 2, 3)), ("r", (5, 6, 7))):
        a = hips + sk.offsets[thigh]
        b, c = a + sk.offsets[shin], a + sk.offsets[shin] + sk.offsets[foot]
        qa, qb = two_bone_ik(a, b, c, ankles[side], pole=np.array([0.0, 0.0, 1.0]))
        rot[:, thigh] = qa
        rot[:, shin] = R.quat_mul(R.quat_conjugate(qa), R.quat_mul(qb, qa))
        rot[:, foot] = R.quat_conjugate(R.quat_mul(qb, qa))
    return Motion(sk, FPS, rot, pos)


def step(slide: float = 0.0, hips_speed: float = 0.02, plant: tuple[float, float] = (0.1, 0.08),
         F: int = 60) -> Motion:
    """The left foot swings in, is planted on frames 10-19 (sliding ``slide`` per frame forward), then lifts;
    the right foot flies 40 cm up all along. The hips walk forward at ``hips_speed`` per frame."""
    sk = biped()
    t = np.arange(F, dtype=float)
    hips = np.stack([np.zeros(F), np.full(F, 0.95), hips_speed * t], axis=-1)
    p0 = np.array([plant[0], plant[1], hips_speed * 14.5])
    left = np.tile(p0, (F, 1))
    before, after = t < 10, t > 19
    left[before] += np.stack([0 * t, 0.02 * (10 - t), -0.05 * (10 - t)], axis=-1)[before]
    lift = np.minimum(t - 19, 6)
    left[after] += np.stack([0 * t, 0.02 * lift, 0.05 * lift], axis=-1)[after]
    late = t > 25
    left[late, 2] += hips_speed * (t[late] - 25)
    left[:, 2] += slide * np.clip(t - 10, 0, 9)  # sliding on the ground, then on from there
    right = hips + np.array([-0.1, -0.55, 0.05])
    return author(sk, hips, {"l": left, "r": right})


def world(motion: Motion) -> np.ndarray:
    return fk(motion.rotations, motion.positions, motion.skeleton.parents)[1]


def bone_lengths(motion: Motion) -> np.ndarray:
    P = world(motion)
    par = motion.skeleton.parents
    return np.linalg.norm(P[:, 1:] - P[:, par[1:]], axis=-1)


def check_exact_keys_and_bones(before: Motion, after: Motion, keys) -> None:
    frames = np.asarray(keys.frames if isinstance(keys, Keys) else keys)
    assert np.array_equal(after.rotations[frames], before.rotations[frames])
    assert np.array_equal(after.positions[frames], before.positions[frames])
    # only the hips' translation changes, and the rotations of thighs, shins and feet
    pos_changed = np.flatnonzero(np.any(after.positions != before.positions, axis=(0, 2)))
    rot_changed = np.flatnonzero(np.any(after.rotations != before.rotations, axis=(0, 2)))
    rig = make_rig(before.skeleton)
    legs = {j for chain in foot_chains(rig).values() for j in chain[:3]}
    assert set(pos_changed) <= {rig.roles.hips} and set(rot_changed) <= legs
    # every bone keeps its length (the hips' translation from a parent above them is no bone)
    bones = np.arange(1, before.num_joints) != rig.roles.hips
    scale = np.abs(before.skeleton.offsets).max()
    np.testing.assert_allclose(bone_lengths(after)[:, bones], bone_lengths(before)[:, bones], rtol=0,
                               atol=1e-9 * scale)


# --- contacts ---------------------------------------------------------------------------------------------------


def test_a_planted_foot_is_in_contact_and_a_flying_foot_never():
    m = step()
    rig = make_rig(m.skeleton)
    assert [r for r, _ in contact_joints(rig)] == ["foot_l", "toe_l", "foot_r", "toe_r"]
    assert foot_chains(rig) == {"l": (1, 2, 3, 4), "r": (5, 6, 7, 8)}
    labels = contacts(m, rig)
    assert labels.shape == (60, 4) and labels.dtype == bool
    assert np.array_equal(np.flatnonzero(labels[:, 0]), np.arange(10, 20))  # the ankle: exactly the plant
    assert np.array_equal(np.flatnonzero(labels[:, 1]), np.arange(10, 20))  # the level foot's toe with it
    assert not labels[:, 2:].any()  # the flying foot: none
    # the ground: the lowest foot joint (the planted toe, 3 cm up), the same from keys holding the plant
    assert ground_height(m, rig) == pytest.approx(0.03, abs=1e-12)
    assert ground_height(m, rig, keys=[0, 15, 59]) == pytest.approx(0.03, abs=1e-12)
    assert ground_height(m, rig, ground=0.5) == 0.5
    # a ground far below: nothing is near it; labels are a pure function of the motion
    assert not contacts(m, rig, ground=-1.0).any()
    assert np.array_equal(contacts(m, m.skeleton), labels)


def test_hysteresis_and_the_minimum_length_by_hand():
    """One joint, 1 m hip height, still horizontally: heights in units of the hip height."""
    s = FootSettings(height_enter=0.03, height_leave=0.05, min_contact_s=0.1)  # 3 frames at 30 fps
    h = np.array([0.2, 0.04, 0.02, 0.045, 0.045, 0.02, 0.06, 0.04, 0.02, 0.02, 0.07, 0.0, 0.0, 0.0, 0.07])
    p = np.zeros((len(h), 1, 3))
    p[:, 0, 1] = h
    got = label_contacts(p, np.zeros(1), fps=30.0, up_axis="Y", hip_height=1.0, settings=s)[:, 0]
    # 0.04 is not low enough to enter but low enough to stay; 0.06 leaves; runs under 3 frames go
    want = [0, 0, 1, 1, 1, 1, 0, 0, 0, 0, 0, 1, 1, 1, 0]
    want[8:10] = [0, 0]  # entered at 8, 2 frames long: dropped
    assert got.astype(int).tolist() == want
    # speed: a joint sliding faster than speed_leave is never in contact, however low
    p2 = np.zeros((10, 1, 3))
    p2[:, 0, 0] = np.arange(10) * 1.1 / 30  # 1.1 hip heights per second
    assert not label_contacts(p2, 0.0, fps=30.0, up_axis="Y", hip_height=1.0).any()
    p2[:, 0, 0] = np.arange(10) * 0.5 / 30
    assert label_contacts(p2, 0.0, fps=30.0, up_axis="Y", hip_height=1.0).all()


def test_labels_batch_over_leading_dimensions():
    rng = np.random.default_rng(0)
    p = np.cumsum(rng.normal(scale=0.01, size=(3, 2, 40, 4, 3)), axis=2)
    floor = rng.normal(scale=0.02, size=(3, 2, 4))
    batch = label_contacts(p, floor, fps=30.0, up_axis="Z", hip_height=0.5)
    assert batch.shape == (3, 2, 40, 4) and batch.any() and not batch.all()
    for i in range(3):
        for j in range(2):
            one = label_contacts(p[i, j], floor[i, j], fps=30.0, up_axis="Z", hip_height=0.5)
            assert np.array_equal(batch[i, j], one)


def test_settings_are_checked_and_name_their_field():
    with pytest.raises(UsageError) as e:
        FootSettings(height_enter=0.1, height_leave=0.05)
    assert e.value.params == ("height_enter", "height_leave")
    with pytest.raises(UsageError) as e:
        FootSettings(ease_s=-1)
    assert e.value.params == ("ease_s",)
    assert FootSettings().ease_frames(30) == 6 and FootSettings().min_contact_frames(120) == 12
    with pytest.raises(UsageError) as e:
        lock_feet(step(), biped(), ground="floor")
    assert e.value.params == ("ground",)


# --- locking ---------------------------------------------------------------------------------------------------


def test_locked_feet_do_not_move_in_contact_and_keys_and_bones_stay_exact():
    m = step(slide=0.012)  # the planted foot slides 36 cm/s, as generated ones do
    rig = make_rig(m.skeleton)
    keys = Keys([0, 15, 40, 59])
    labels = contacts(m, rig, keys=keys)
    assert np.array_equal(np.flatnonzero(labels[:, 0]), np.arange(10, 20))
    out, report = lock_feet(m, rig, keys)
    H = rig.hip_height
    P, P0 = world(out), world(m)
    ankle = P[10:20, 3]
    # held at the key's position (frame 15 is in the interval), horizontally and vertically
    assert np.abs(ankle - P0[15, 3]).max() < 1e-6 * H
    assert np.abs(P[10:20, 4] - P[15, 4]).max() < 1e-6 * H  # the toe follows the still, level foot
    check_exact_keys_and_bones(m, out, keys)
    # the foot keeps its world orientation
    W, W0 = out.world()[0], m.world()[0]
    assert R.quat_angle(W[:, 3], W0[:, 3]).max() < 1e-9
    # the report: 36 cm/s before, none after, in the motion's units
    assert report["skating_before"] == pytest.approx(0.36, rel=0.05)
    assert report["skating_after"] < 1e-6
    assert report["intervals"] == 2 and report["frames_in_contact"] == 10 and report["unreached_frames"] == 0
    assert report["hip_drop_max"] == 0.0 and report["ground"] == pytest.approx(0.03, abs=1e-9)
    # easing: continuous. The correction (locked - free) changes per frame by no more than a quarter of the
    # motion's own largest per-frame change; for the ankle, by the slide it undoes plus the offset at the
    # interval's ends (6 cm ahead: the key is 5 slid frames in) times the smoothstep's steepest slope
    own = np.linalg.norm(np.diff(P0, axis=0), axis=-1).max()
    change = np.linalg.norm(np.diff(P - P0, axis=0), axis=-1)
    assert change.max() <= 0.25 * own
    ease = FootSettings().ease_frames(FPS)
    assert change[:, 3].max() <= 0.012 + 1.5 * 0.06 / (ease + 1) + 1e-9
    # outside the eases (6 frames) nothing changed
    assert np.array_equal(out.rotations[:4], m.rotations[:4]) and np.array_equal(out.rotations[26:], m.rotations[26:])


def test_without_a_key_in_the_interval_the_foot_holds_its_median_and_keys_at_the_edges_stay_exact():
    m = step(slide=0.01)
    keys = Keys([0, 8, 22, 59])  # keys inside both eases, none in the contact
    out, report = lock_feet(m, m.skeleton, keys)
    P, P0 = world(out), world(m)
    median = np.median(P0[10:20, 3], axis=0)
    assert np.abs(P[10:20, 3] - median).max() < 1e-6 * make_rig(m.skeleton).hip_height
    check_exact_keys_and_bones(m, out, keys)
    assert report["skating_after"] < 1e-6 < report["skating_before"]


def test_two_keys_in_one_contact_move_the_foot_from_one_to_the_other():
    m = step(slide=0.012)
    keys = Keys([0, 12, 17, 59])
    out, _ = lock_feet(m, m.skeleton, keys)
    P, P0 = world(out), world(m)
    tol = 1e-6 * make_rig(m.skeleton).hip_height
    assert np.abs(P[10:13, 3] - P0[12, 3]).max() < tol  # the first key's position up to it
    assert np.abs(P[17:20, 3] - P0[17, 3]).max() < tol  # the last one's from it
    u = ((np.arange(12, 18) - 12) / 5)[:, None]
    assert np.abs(P[12:18, 3] - ((1 - u) * P0[12, 3] + u * P0[17, 3])).max() < tol  # linear between
    check_exact_keys_and_bones(m, out, keys)


def test_the_hips_come_down_where_a_leg_cannot_reach():
    # a nearly straight planted leg under hips walking at 0.45 m/s; the key at the end of the plant holds the
    # foot 12 cm ahead of where it lands, out of reach of the hips at their height in the first frames
    m = step(slide=0.013, hips_speed=0.015, plant=(0.1, 0.035))
    rig = make_rig(m.skeleton)
    keys = Keys([0, 19, 59])
    assert np.array_equal(np.flatnonzero(contacts(m, rig, keys=keys)[:, 0]), np.arange(10, 20))
    out, report = lock_feet(m, rig, keys, settings=FootSettings(max_hip_drop=0.1))  # off by default
    P, P0 = world(out), world(m)
    assert report["hip_drop_max"] > 0.01 and report["unreached_frames"] == 0
    assert np.abs(P[10:20, 3] - P0[19, 3]).max() < 1e-6 * rig.hip_height
    drop = P0[:, 0, 1] - P[:, 0, 1]
    assert np.all(drop >= 0) and drop[10] > 0.01 and np.all(drop[keys.frames] == 0)
    assert np.array_equal(P[:, 0, [0, 2]], P0[:, 0, [0, 2]])  # along the up axis only
    assert np.abs(np.diff(drop)).max() < 0.25 * report["hip_drop_max"]  # smoothly
    check_exact_keys_and_bones(m, out, keys)
    # the flying foot keeps its path while the hips come down
    np.testing.assert_allclose(P[:, 7], P0[:, 7], atol=1e-9)
    # with the drop capped, the foot gives instead, and the report says where
    _, capped_report = lock_feet(m, rig, keys, settings=FootSettings(max_hip_drop=0.002))
    assert capped_report["hip_drop_max"] <= 0.002 * rig.hip_height + 1e-12 and capped_report["unreached_frames"] > 0


def z_up_and_scaled(m: Motion, scale: float) -> Motion:
    """``m`` turned a quarter about X (Y up -> Z up) and scaled by ``scale``."""
    q = R.quat_from_rotvec(np.array([np.pi / 2, 0, 0]))
    sk = m.skeleton
    ends = tuple((j, scale * R.quat_rotate(q, o)) for j, o in sk.end_sites)
    zsk = sk.replace(offsets=scale * R.quat_rotate(q, sk.offsets), up_axis="Z", end_sites=ends)
    rot = R.quat_mul(R.quat_mul(q, m.rotations), R.quat_conjugate(q))
    return Motion(zsk, m.fps, rot, scale * R.quat_rotate(q, m.positions))


def test_z_up_and_a_24_unit_rig_lock_the_same():
    m = step(slide=0.012)
    scale = 24 / 1.55  # the biped is 1.55 m tall: CMU's 24 units
    z = z_up_and_scaled(m, scale)
    rig, zrig = make_rig(m.skeleton), make_rig(z.skeleton)
    assert zrig.hip_height == pytest.approx(scale * rig.hip_height)
    keys = Keys([0, 15, 40, 59])
    assert np.array_equal(contacts(z, zrig, keys=keys), contacts(m, rig, keys=keys))
    out, report = lock_feet(m, rig, keys)
    zout, zreport = lock_feet(z, zrig, keys)
    q = R.quat_from_rotvec(np.array([np.pi / 2, 0, 0]))
    np.testing.assert_allclose(world(zout), scale * R.quat_rotate(q, world(out)), atol=1e-9 * scale)
    assert zreport["skating_before"] == pytest.approx(scale * report["skating_before"])
    check_exact_keys_and_bones(z, zout, keys)


def test_other_frame_rates_give_the_same_contacts():
    m = step()
    rig = make_rig(m.skeleton)
    # the same motion at 60 fps: every frame doubled by linear interpolation of the world positions' source
    labels = contacts(m, rig)
    m60 = m.replace(fps=60.0)
    slow = contacts(m60, rig)  # the same frames twice as fast: speeds double, so fewer contacts, never more
    assert not (slow & ~labels).any()
    np.testing.assert_array_equal(contacts(m60, rig, settings=FootSettings(speed_enter=1.2, speed_leave=2.0,
                                                                            min_contact_s=0.05, ease_s=0.1)), labels)


def test_a_rig_without_legs_is_a_data_error():
    lamp = lamp_skeleton()
    motion = Motion.rest(lamp, 5)
    for call in (lambda: foot_chains(lamp), lambda: contacts(motion, lamp), lambda: lock_feet(motion, lamp)):
        with pytest.raises(DataError) as e:
            call()
        assert "thigh_l" in str(e.value) and "foot_r" in str(e.value) and "upper_arm" not in str(e.value)


def held_still(P: np.ndarray, labels: np.ndarray, keys: np.ndarray, tol: float) -> int:
    """Check that each joint of ``P (F, n, 3)`` is still over each of its contact intervals holding at most one
    key (with two keys it moves from one's position to the other's); returns how many intervals were checked."""
    checked = 0
    for c in range(labels.shape[1]):
        edges = np.diff(np.pad(labels[:, c].astype(int), 1))
        for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            if np.sum((keys >= s) & (keys < e)) <= 1:
                assert np.abs(P[s:e, c] - P[s, c]).max() < tol
                checked += 1
    return checked


def test_the_mixamo_walk_made_to_slide():
    m = load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")  # a walk, 69 frames at 30 fps, cm
    rig = make_rig(m.skeleton)
    pos = m.positions.copy()
    pos[:, rig.roles.hips, 0] += 0.5 * np.arange(m.num_frames)  # sideways, 15 cm/s: the feet slide
    walk = m.replace(positions=pos)
    keys = Keys.every(20, m.num_frames)
    labels = contacts(walk, rig, keys=keys)
    assert np.mean(labels == contacts(m, rig, keys=keys)) > 0.95  # the slide is slow: nearly the same contacts
    out, report = lock_feet(walk, rig, keys, labels=labels, settings=FootSettings(max_hip_drop=0.1))
    check_exact_keys_and_bones(walk, out, keys)
    assert report["intervals"] >= 8 and report["unreached_frames"] == 0
    assert report["skating_after"] < 0.5 * report["skating_before"]
    cols = [j for _, j in contact_joints(rig)]
    toes = [i for i, (role, _) in enumerate(contact_joints(rig)) if role.startswith("toe")]
    assert held_still(world(out)[:, cols][:, toes], labels[:, toes], keys.frames, 1e-6 * rig.hip_height) >= 2
    # the hips come down little, if at all (a real walk, its feet held)
    assert 0 <= report["hip_drop_max"] < 0.03 * rig.hip_height


def test_bandai_rig_and_the_time_of_2048_frames(capsys):
    path = BVH_FIXTURES / "dataset-1_walk_normal_002.bvh"
    if not path.exists():
        pytest.skip(f"needs {path}")
    clip = load(path)
    rig = make_rig(clip.skeleton)
    keys = Keys.every(10, clip.num_frames)
    out, report = lock_feet(clip, rig, keys)
    check_exact_keys_and_bones(clip, out, keys)
    assert report["skating_after"] <= report["skating_before"]
    reps = -(-2048 // clip.num_frames)
    long = Motion(clip.skeleton, clip.fps, np.tile(clip.rotations, (reps, 1, 1))[:2048],
                  np.tile(clip.positions, (reps, 1, 1))[:2048])
    keys = Keys.every(30, 2048)
    lock_feet(long, rig, keys)  # warm
    start = time.perf_counter()
    locked, long_report = lock_feet(long, rig, keys)
    seconds = time.perf_counter() - start
    check_exact_keys_and_bones(long, locked, keys)
    with capsys.disabled():
        print(f"\nlock_feet: 2048 frames x {long.num_joints} joints in {seconds * 1e3:.1f} ms "
              f"({long_report['intervals']} intervals)")
