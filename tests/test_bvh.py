"""BVH reading and writing: fixtures, random hierarchies and layouts, exactness, continuity."""

from pathlib import Path

import numpy as np
import pytest
from conftest import BVH_FIXTURES, DATA, shared_fixtures
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from keyfill import rotations as R
from keyfill.io import bvh
from keyfill.motion import Motion

LOCAL_FIXTURES = sorted(DATA.glob("*.bvh"))


def assert_same_motion(a: Motion, b: Motion, rot_tol=1e-9, pos_tol=1e-9):
    assert a.skeleton.names == b.skeleton.names
    assert np.array_equal(a.skeleton.parents, b.skeleton.parents)
    assert a.skeleton.channels == b.skeleton.channels
    np.testing.assert_allclose(a.skeleton.offsets, b.skeleton.offsets, atol=pos_tol)
    assert a.num_frames == b.num_frames
    if a.num_frames:
        assert R.quat_angle(a.rotations, b.rotations).max() < rot_tol
        assert np.abs(a.positions - b.positions).max() < pos_tol


def round_trip(m: Motion) -> Motion:
    return bvh.parse(bvh.dumps(m))


def assert_same_text(a: str, b: str, atol: float = 1e-8):
    """Two BVH texts line for line the same but for numbers within ``atol``: near gimbal lock (a middle
    angle of about +-90 degrees) the first and third angles of a rotation are ill-conditioned, about
    1e-16 / cos(middle angle) degrees, which 12 significant digits can show."""
    la, lb = a.splitlines(), b.splitlines()
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        if x != y:
            wa, wb = x.split(), y.split()
            assert len(wa) == len(wb), (x, y)
            np.testing.assert_allclose(np.array(wa, dtype=float), np.array(wb, dtype=float), rtol=0, atol=atol)


@pytest.mark.parametrize("path", LOCAL_FIXTURES, ids=lambda p: p.name)
def test_local_fixture_round_trip(path):
    m = bvh.read(path)
    assert_same_motion(m, round_trip(m), rot_tol=1e-6, pos_tol=1e-6)
    assert [len(o) for _, o in m.skeleton.end_sites] == [3] * len(m.skeleton.end_sites)


def test_shared_fixtures_round_trip_exactly():
    for path in shared_fixtures():
        m = bvh.read(path)
        m2 = round_trip(m)
        assert_same_motion(m, m2, rot_tol=1e-6, pos_tol=1e-6)
        height = np.ptp(m.skeleton.rest_world_positions()[:, 1])
        assert np.abs(m.world_positions() - m2.world_positions()).max() < 1e-6 * height


def test_fixture_facts():
    cmu = bvh.read(DATA / "cmu_02_03_cgspeed_first4frames.bvh")
    assert (cmu.num_frames, cmu.num_joints, cmu.skeleton.num_channels, cmu.fps) == (4, 31, 96, 120.0)
    assert set(cmu.skeleton.euler_orders) == {"ZYX"}
    mix = bvh.read(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")
    assert (mix.num_frames, mix.num_joints, mix.skeleton.num_channels, mix.fps) == (69, 55, 168, 30.0)
    assert mix.skeleton.names[0] == "mixamorig:Hips"


def test_edge_layouts_fixture():
    """Several ROOTs, 0/1/2/3/6-channel joints, positions on an inner joint, CRLF, tabs, exponents."""
    m = bvh.read(DATA / "edge_layouts_crlf.bvh")
    sk = m.skeleton
    assert sk.names == ("mixamo:Hips|a.b", "Spine-1", "Head", "Slider", "Prop", "Lid")
    assert list(sk.parents) == [-1, 0, 1, 0, -1, 4]
    assert [len(c) for c in sk.channels] == [6, 2, 0, 3, 3, 1]
    assert sk.euler_orders == ("YXZ", "XZY", "XYZ", "YXZ", "ZXY", "ZXY")
    np.testing.assert_allclose(sk.offsets[1], [0, 15, 0])  # "1.5e1"
    assert m.fps == 24.0  # 0.0416667 snapped
    # Frame 1 values: root position and the inner joint's X/Z translation (Y stays the offset's).
    np.testing.assert_allclose(m.positions[1, 0], [1.5, 91, -0.24])
    np.testing.assert_allclose(m.positions[1, 3], [3.5, 0, 0.75])
    # Frame 1: Slider turns -179.5 degrees about Y, Lid 12.5 degrees about Z.
    slider = R.euler_to_quat(np.deg2rad([-179.5, 0, 0]), "YXZ")
    lid = R.euler_to_quat(np.deg2rad([12.5, 0, 0]), "ZXY")
    assert R.quat_angle(m.rotations[1, 3], slider) < 1e-12
    assert R.quat_angle(m.rotations[1, 5], lid) < 1e-12
    assert_same_motion(m, round_trip(m), rot_tol=1e-9, pos_tol=1e-9)


def test_written_numbers_round_trip_and_are_not_fixed_point():
    m = bvh.read(DATA / "edge_layouts_crlf.bvh")
    text = bvh.dumps(m)
    assert "0.001" in text and "0.00100000" not in text  # %.12g, never %f padding
    assert bvh.dumps(bvh.parse(text)) == text  # writing is a fixed point


def test_a_rotation_near_gimbal_lock_writes_stably_to_rounding():
    """Hypothesis found it: Y at -89.97 degrees in an XYZ joint; rewriting the written file moves the third
    angle by 1e-11 degrees (12 significant digits show it), the rotation by less than 1e-12 rad."""
    text = ("HIERARCHY\nROOT j\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Xrotation Yrotation Zrotation\n\tEnd Site\n"
            "\t{\n\t\tOFFSET 0 1 0\n\t}\n}\nMOTION\nFrames: 2\nFrame Time: 0.0333333\n"
            "54.085414 -110.137699 108.491008\n146.567710 -90.027401 177.951948\n")
    m = bvh.parse(text)
    once = bvh.dumps(m)
    twice = bvh.dumps(bvh.parse(once))
    assert_same_text(twice, once, atol=1e-9)
    assert R.quat_angle(bvh.parse(twice).rotations, m.rotations).max() < 1e-12


def test_written_euler_curves_are_continuous():
    """A joint spinning steadily past 180 degrees is written without 360-degree jumps."""
    m = bvh.read(DATA / "edge_layouts_crlf.bvh")
    F = 60
    angles = np.zeros((F, 3))
    angles[:, 0] = np.linspace(0, 4 * np.pi, F)  # two full turns about Y (root order YXZ)
    angles[:, 1] = 0.3
    rot = np.repeat(m.rotations[:1], F, axis=0)
    rot[:, 0] = R.euler_to_quat(angles, "YXZ")
    pos = np.repeat(m.positions[:1], F, axis=0)
    spin = m.replace(rotations=rot, positions=pos)
    values = bvh.pose_to_channels(spin)
    root_y = values[:, 3]  # root channels: X/Y/Z position, then Yrotation
    assert np.abs(np.diff(root_y)).max() < 20  # degrees per frame: no wraps
    assert root_y[-1] - root_y[0] == pytest.approx(720, abs=1e-6)


# --- random hierarchies and channel layouts ---------------------------------------------

AXES = "XYZ"


@st.composite
def channel_layout(draw):
    rot_n = draw(st.integers(0, 3))
    pos_n = draw(st.sampled_from([p for p in range(4) if p + rot_n not in (4, 5)]))
    rot = draw(st.permutations(AXES))[:rot_n]
    pos = draw(st.permutations(AXES))[:pos_n]
    chans = [a + "position" for a in pos] + [a + "rotation" for a in rot]
    order = draw(st.permutations(range(len(chans)))) if chans else []
    return [chans[i] for i in order]


@st.composite
def bvh_text(draw):
    J = draw(st.integers(1, 7))
    parents = [-1] + [draw(st.one_of(st.just(-1), st.integers(0, j - 1))) if j else -1 for j in range(1, J)]
    layouts = [draw(channel_layout()) for _ in range(J)]
    F = draw(st.integers(0, 5))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    names = [f"j{j}:{draw(st.sampled_from(['a', 'B.c', 'x-y', 'L|1']))}" for j in range(J)]
    children = {j: [k for k in range(J) if parents[k] == j] for j in range(J)}
    lines = ["HIERARCHY"]

    def joint(j, depth):
        ind = "\t" * depth
        lines.append(f"{ind}{'ROOT' if parents[j] < 0 else 'JOINT'} {names[j]}")
        lines.append(ind + "{")
        lines.append(f"{ind}\tOFFSET " + " ".join(f"{v:.6f}" for v in rng.uniform(-20, 20, 3)))
        lines.append(f"{ind}\tCHANNELS {len(layouts[j])} {' '.join(layouts[j])}".rstrip())
        for k in children[j]:
            joint(k, depth + 1)
        if not children[j]:
            lines.append(f"{ind}\tEnd Site")
            lines.append(f"{ind}\t{{\n{ind}\t\tOFFSET 0 1 0\n{ind}\t}}")
        lines.append(ind + "}")

    # Roots in index order keep the file order equal to the joint order.
    for j in range(J):
        if parents[j] < 0:
            joint(j, 0)
    lines += ["MOTION", f"Frames: {F}", "Frame Time: 0.0333333"]
    C = sum(len(c) for c in layouts)
    for _ in range(F):
        lines.append(" ".join(f"{v:.6f}" for v in rng.uniform(-180, 180, C)))
    return "\n".join(lines) + "\n"




@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=bvh_text())
def test_random_hierarchies_round_trip(text):
    m = bvh.parse(text)
    m2 = round_trip(m)
    assert_same_motion(m, m2, rot_tol=1e-9, pos_tol=1e-9)
    assert_same_text(bvh.dumps(m2), bvh.dumps(m))
    if m.num_frames:
        np.testing.assert_allclose(m.world_positions(), m2.world_positions(), atol=1e-9)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=bvh_text())
def test_channel_values_are_read_as_written(text):
    """Angles and translations come back as the file wrote them (modulo equivalent Euler angles)."""
    m = bvh.parse(text)
    if not m.num_frames:
        return
    raw = np.array([[float(v) for v in line.split()] for line in text.split("Frame Time: 0.0333333\n")[1].splitlines()])
    if raw.size == 0:
        return
    written = bvh.pose_to_channels(m)
    col = 0
    for chans in m.skeleton.channels:
        n = len(chans)
        block_raw, block_w = raw[:, col : col + n], written[:, col : col + n]
        rot_cols = [i for i, c in enumerate(chans) if c.endswith("rotation")]
        pos_cols = [i for i, c in enumerate(chans) if c.endswith("position")]
        np.testing.assert_allclose(block_w[:, pos_cols], block_raw[:, pos_cols], atol=1e-9)
        if rot_cols:
            order = "".join(chans[i][0] for i in rot_cols)
            full = order + "".join(a for a in AXES if a not in order)
            pad = np.zeros((len(raw), 3))
            pad_w = np.zeros((len(raw), 3))
            pad[:, : len(rot_cols)] = block_raw[:, rot_cols]
            pad_w[:, : len(rot_cols)] = block_w[:, rot_cols]
            q_raw = R.euler_to_quat(np.deg2rad(pad), full)
            q_w = R.euler_to_quat(np.deg2rad(pad_w), full)
            assert R.quat_angle(q_raw, q_w).max() < 1e-9
        col += n


def test_large_file_parses_in_bulk(tmp_path: Path):
    """10,000 frames of 132 channels parse and write back exactly."""
    m = bvh.read(DATA / "cmu_02_03_cgspeed_first4frames.bvh")
    big = m.frames(np.arange(10_000) % m.num_frames)
    text = bvh.dumps(big)
    again = bvh.parse(text)
    assert again.num_frames == 10_000
    assert_same_motion(big, again, rot_tol=1e-9, pos_tol=1e-9)


@settings(max_examples=200, deadline=None)
@given(
    columns=st.lists(
        st.one_of(
            st.floats(-1e6, 1e6, allow_nan=False),  # a column that may be constant
            st.tuples(st.floats(-1e3, 1e3, allow_nan=False), st.floats(-1e-9, 1e-9, allow_nan=False)),
            st.just("signed zeros"),
        ),
        min_size=1,
        max_size=8,
    ),
    frames=st.integers(1, 6),
    seed=st.integers(0, 2**32 - 1),
)
def test_line_template_prints_every_value_as_percent_12g(columns, frames, seed):
    """Constant columns folded into the line template print exactly as per-value %.12g would, with the rows
    given in blocks of any sizes (empty ones too)."""
    rng = np.random.default_rng(seed)
    cols = []
    for c in columns:
        if c == "signed zeros":  # 0.0 and -0.0 print differently
            cols.append(np.copysign(np.zeros(frames), rng.choice([1.0, -1.0], frames)))
        elif isinstance(c, tuple):  # nearly constant: tiny noise, possibly flipping the sign of zero
            base, eps = c
            cols.append(base + eps * rng.standard_normal(frames) * rng.integers(0, 2, frames))
        else:
            cols.append(np.full(frames, c) * rng.choice([1.0, -1.0]) if rng.random() < 0.2 else np.full(frames, c))
    values = np.stack(cols, axis=1)
    cuts = np.sort(rng.integers(0, frames + 1, rng.integers(0, 3)))  # gathered a block of rows at a time
    line, varying = bvh._line_template(values.shape[1], np.split(values, cuts))
    got = [line % tuple(row) for row in values[:, varying].tolist()]
    want = [" ".join(bvh.NUMBER_FORMAT % v for v in row) for row in values.tolist()]
    assert got == want


# --- values as they came (issue 32) -------------------------------------------------------------------------------


def _completed(src: Path, tmp_path: Path, keys: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The channel values of ``src`` and of its cubic completion from ``keys`` written as BVH by io.save."""
    from keyfill import io
    from keyfill.learn.registry import complete
    from keyfill.motion import Keys

    out = tmp_path / f"{src.stem}_completed.bvh"
    io.save(complete(io.load(src), Keys(keys), "cubic").motion, out, source=src)
    return bvh.parse_values(src.read_bytes())[2], bvh.parse_values(out.read_bytes())[2]


# the shared fixtures where ../shared is beside the checkout (collected without it: a glob of an absent folder is empty)
@pytest.mark.parametrize("path", LOCAL_FIXTURES + sorted(BVH_FIXTURES.glob("*.bvh")), ids=lambda p: p.name)
def test_key_frames_of_a_completed_bvh_carry_the_inputs_own_channel_values(path, tmp_path):
    F = bvh.read(path).num_frames
    if F < 3:
        pytest.skip("fewer than 3 frames")
    keys = [0, F // 2, F - 1]
    given, written = _completed(path, tmp_path, keys)
    assert np.abs(written[keys] - given[keys]).max(initial=0.0) <= 1e-6  # degrees (and file units)


def test_the_frames_between_keys_are_unwrapped_towards_their_key(tmp_path):
    """edge_layouts_crlf.bvh turns a joint through +-180 degrees: its Euler channels written without the input
    come back a whole turn away from the input's at a key; with it, the key's own numbers, for the same
    rotations."""
    from keyfill import io
    from keyfill.learn.registry import complete
    from keyfill.motion import Keys

    src = DATA / "edge_layouts_crlf.bvh"
    motion = io.load(src)
    keys = [0, motion.num_frames // 2, motion.num_frames - 1]
    filled = complete(motion, Keys(keys), "cubic").motion
    given = bvh.parse_values(src.read_bytes())[2]
    plain = bvh.parse_values(bvh.dumps(filled))[2]
    assert np.abs(plain[keys] - given[keys]).max() == pytest.approx(360.0)  # what the writer alone gives
    _, written = _completed(src, tmp_path, keys)
    assert np.abs(written[keys] - given[keys]).max() <= 1e-6
    sk = filled.skeleton  # the same rotations either way (whole turns, or the other Euler solution at a key)
    assert R.quat_angle(bvh.channels_to_pose(written, sk)[0], bvh.channels_to_pose(plain, sk)[0]).max() < 1e-9


def test_a_template_of_another_layout_changes_nothing(tmp_path):
    cmu, mixamo = DATA / "cmu_02_03_cgspeed_first4frames.bvh", DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
    motion = bvh.read(cmu)
    values = bvh.pose_to_channels(motion)
    assert np.array_equal(bvh.follow_template(values, motion, mixamo), values)
    assert np.array_equal(bvh.follow_template(values, motion, tmp_path / "missing.bvh"), values)


def test_written_bvh_has_no_negative_zero_of_its_own():
    motion = bvh.read(DATA / "edge_layouts_crlf.bvh")
    tokens = bvh.dumps(motion).split()
    assert "-0" not in tokens
