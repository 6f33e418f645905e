"""The lamp as a Motion: skeleton, animation variables, files, and agreement with the physics model."""

from __future__ import annotations

import numpy as np
import pytest

from keyfill import io
from keyfill.characters.lamp import (
    DIMENSIONS,
    VARIABLE_NAMES,
    VARIABLES,
    from_variables,
    is_lamp,
    lamp_skeleton,
    to_variables,
)
from keyfill.errors import DataError
from keyfill.motion import Keys, Motion


def random_variables(rng: np.random.Generator, frames: int = 12) -> np.ndarray:
    v = np.empty((frames, 6))
    v[:, :2] = rng.normal(size=(frames, 2))
    v[:, 2:] = np.cumsum(rng.normal(scale=0.6, size=(frames, 4)), axis=0)  # drifts past +-pi
    return v


def test_skeleton_layout():
    sk = lamp_skeleton()
    assert sk.names == ("base", "leg", "neck", "head")
    assert sk.parents.tolist() == [-1, 0, 1, 2]
    assert sk.channels[0] == ("Xposition", "Yposition", "Zrotation")
    assert all(c == ("Zrotation",) for c in sk.channels[1:])
    assert sk.meters_per_unit == 1.0 and sk.up_axis == "Y"
    assert sk.num_channels == 6 == len(VARIABLES)
    assert VARIABLE_NAMES == ("base_x", "base_y", "base_angle", "leg_angle", "neck_angle", "head_angle")
    assert [v.unit for v in VARIABLES] == ["m", "m", "rad", "rad", "rad", "rad"]
    assert np.allclose(sk.offsets[1:, 1], [DIMENSIONS.base_height, DIMENSIONS.leg_length, DIMENSIONS.neck_length])
    assert is_lamp(sk)
    assert not is_lamp(sk.replace(names=("base", "leg", "neck", "lamp")))
    six = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert not is_lamp(sk.replace(channels=(six,) + sk.channels[1:]))


def test_variables_round_trip_and_pose():
    rng = np.random.default_rng(0)
    v = random_variables(rng)
    m = from_variables(v, 60.0, keys=Keys([0, 5, 11]))
    assert m.keys.to_list() == [0, 5, 11] and m.fps == 60.0
    np.testing.assert_allclose(to_variables(m), v, atol=1e-12)
    # Straight up with the base at (x, y): hinges stacked along +Y.
    up = from_variables(np.array([[0.3, 0.1, 0.0, 0.0, 0.0, 0.0]]), 30.0)
    d = DIMENSIONS
    np.testing.assert_allclose(
        up.world_positions()[0, :, :2],
        [[0.3, 0.1], [0.3, 0.1 + d.base_height], [0.3, 0.1 + d.base_height + d.leg_length],
         [0.3, 0.1 + d.base_height + d.leg_length + d.neck_length]],
        atol=1e-12,
    )
    # A positive leg angle tips the leg's top towards -X.
    tip = from_variables(np.array([[0, 0, 0, 0.5, 0, 0]]), 30.0).world_positions()[0, 2]
    assert tip[0] == pytest.approx(-d.leg_length * np.sin(0.5))


@pytest.mark.parametrize("suffix", [".bvh", ".usda"])
def test_files_keep_the_variables(tmp_path, suffix):
    rng = np.random.default_rng(1)
    v = random_variables(rng)
    m = from_variables(v, 60.0, keys=Keys([0, 6, 11]))
    io.save(m, tmp_path / f"lamp{suffix}")
    back = io.load(tmp_path / f"lamp{suffix}")
    assert is_lamp(back.skeleton)
    tol = 1e-9 if suffix == ".bvh" else 2e-6  # USD keeps 32-bit floats
    np.testing.assert_allclose(to_variables(back), v, atol=tol)
    if suffix == ".usda":
        assert back.keys.to_list() == [0, 6, 11]


def test_bad_motions_are_refused():
    rng = np.random.default_rng(2)
    m = from_variables(random_variables(rng, 4), 30.0)
    other = Motion.rest(lamp_skeleton().replace(names=("a", "b", "c", "d")), 3)
    with pytest.raises(DataError, match="not a lamp skeleton"):
        to_variables(other)
    rot = m.rotations.copy()
    rot[2, 1] = [np.cos(0.2), np.sin(0.2), 0, 0]  # leg turned about X at frame 2
    with pytest.raises(DataError, match="joint 'leg' rotates out of the lamp's plane at frame 2"):
        to_variables(m.replace(rotations=rot))
    with pytest.raises(DataError, match=r"\(frames, 6\)"):
        from_variables(np.zeros((3, 5)), 30.0)


def test_skeleton_matches_the_physics_model():
    """FK of the lamp skeleton puts every hinge where pybullet puts it, for random states."""
    from keyfill.sim.hops import link_clearances
    from keyfill.sim.physics import LampWorld
    from keyfill.sim.settings import Settings

    settings = Settings()
    rng = np.random.default_rng(3)
    with LampWorld(settings) as w:
        p = w.p
        for _ in range(10):
            state = rng.uniform(-1.0, 1.0, 6) + [0, 0.6, 0, 0, 0, 0]
            for j, value in enumerate(state):
                p.resetJointState(w.lamp, j, value, 0.0, physicsClientId=w.client)
            hinges = [p.getLinkState(w.lamp, j, physicsClientId=w.client)[4] for j in range(2, 6)]
            fk = from_variables(state[None], 30.0).world_positions()[0]
            np.testing.assert_allclose(np.array(hinges), fk, atol=1e-6)  # pybullet reports link frames in float32
            lowest = [p.getAABB(w.lamp, j, physicsClientId=w.client)[0][1] for j in range(2, 6)]
            np.testing.assert_allclose(link_clearances(state[None], settings.dimensions)[0], lowest, atol=1e-9)
