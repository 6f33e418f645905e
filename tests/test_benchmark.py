"""The LaFAN1 protocol: alignment, baselines, splits, errors, the CLI, and the golden run from BVH files."""

import json
from pathlib import Path

import numpy as np
import pytest
from synthetic_corpus import write_corpus

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.cli.main import main
from keyfill.errors import DataError, UsageError
from keyfill.learn.corpus import load_corpus
from keyfill.learn.protocols import lafan1 as B

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
EXPECTED = SHARED / "golden" / "bandai1_lafan_protocol_expected.json"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))


@pytest.fixture
def walkers(tmp_path):
    folder = tmp_path / "walkers"
    write_corpus(folder, styles=("happy", "tired", "calm", "proud"), clips_per_style=3, frames=(80, 140))
    return folder


def test_alignment_centres_and_turns_to_face_x():
    rng = np.random.default_rng(0)
    W, T, J = 4, 20, 3
    q = R.quat_normalize(rng.normal(size=(W, T, J, 4)))
    root = rng.normal(size=(W, T, 3)) * 50
    aq, ar = B.align_windows(q, root, "+Y")
    np.testing.assert_allclose(ar[..., [0, 2]].mean(axis=1), 0.0, atol=1e-9)
    fwd = R.quat_rotate(aq[:, 9, 0], np.array([0.0, 1.0, 0.0]))
    assert np.all(fwd[:, 0] > 0)
    np.testing.assert_allclose(fwd[:, 2], 0.0, atol=1e-9)
    np.testing.assert_array_equal(aq[:, :, 1:], q[:, :, 1:])  # only the root changes
    # heights and distances to the root are kept
    np.testing.assert_allclose(ar[..., 1], root[..., 1], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(np.diff(ar, axis=1), axis=-1),
                               np.linalg.norm(np.diff(root, axis=1), axis=-1), atol=1e-9)


def test_baselines_fill_only_the_transition():
    rng = np.random.default_rng(1)
    q = R.quat_continuous_np(R.quat_normalize(rng.normal(size=(2, 16, 3, 4))), axis=1)
    r = rng.normal(size=(2, 16, 3))
    keys = np.append(np.arange(10), 15)
    zq, zr = interpolate.hold_windows(None, q, r, keys)
    np.testing.assert_array_equal(zq[:, 10:15], np.repeat(q[:, 9:10], 5, axis=1))
    np.testing.assert_array_equal(zr[:, :10], r[:, :10])
    iq, ir = interpolate.linear_windows(None, q, r, keys)
    np.testing.assert_allclose(ir[:, 12], r[:, 9] + 0.5 * (r[:, 15] - r[:, 9]))
    np.testing.assert_allclose(iq[:, 12], R.quat_slerp(q[:, 9], q[:, 15], 0.5), atol=1e-12)


def test_cubic_fills_all_windows_at_once_as_the_spline_does_each():
    from keyfill.interpolate import cubic
    from keyfill.motion import Keys, Motion, Skeleton

    rng = np.random.default_rng(3)
    q = R.quat_continuous_np(R.quat_normalize(rng.normal(size=(3, 21, 4, 4)) + [4, 0, 0, 0]), axis=1)
    r = np.cumsum(rng.normal(size=(3, 21, 3)), axis=1)
    keys = [2, 5, 6, 13, 18]
    hidden = np.setdiff1d(np.arange(21), keys)
    given_q, given_r = q.copy(), r.copy()
    given_q[:, hidden], given_r[:, hidden] = np.nan, np.nan  # only key frames may be read
    cq, cr = interpolate.cubic_windows(None, given_q, given_r, keys)
    skel = Skeleton([f"j{j}" for j in range(4)], [-1, 0, 1, 1], np.ones((4, 3)), [()] * 4)
    for w in range(3):
        pos = np.broadcast_to(skel.offsets, (21, 4, 3)).copy()
        pos[:, 0] = r[w]
        one = cubic(Motion(skel, 30.0, q[w], pos), Keys(keys))
        np.testing.assert_array_equal(cq[w, 2:19], one.rotations[2:19])
        np.testing.assert_array_equal(cr[w, 2:19], one.positions[2:19, 0])
    np.testing.assert_array_equal(cq[:, keys], q[:, keys])
    np.testing.assert_array_equal(cr[:, :2], np.repeat(r[:, 2:3], 2, axis=1))  # before the first key: hold it
    np.testing.assert_array_equal(cq[:, 19:], np.repeat(q[:, 18:19], 2, axis=1))  # after the last key: hold it
    # it carries the velocity of the keys before a gap into it, which interpolation does not
    line = np.arange(21.0)[None, :, None] * [1.0, 0.0, 0.0]
    lr = interpolate.cubic_windows(None, q[:1], line, keys)[1]
    np.testing.assert_allclose(lr[0, 6:14, 0], np.arange(6.0, 14.0), atol=1e-12)


def test_velocity_prefill_leaves_with_the_context_velocity_and_meets_the_keys():
    rng = np.random.default_rng(4)
    q = R.quat_continuous_np(R.quat_normalize(rng.normal(size=(2, 60, 3, 4)) + [3, 0, 0, 0]), axis=1)
    r = np.cumsum(rng.normal(size=(2, 60, 3)), axis=1)
    keys = np.append(np.arange(10), 50)
    given_q, given_r = q.copy(), r.copy()
    given_q[:, 10:50], given_r[:, 10:50] = np.nan, np.nan
    vq, vr = interpolate.velocity_windows(None, given_q, given_r, keys, frames=3.0)
    iq, ir = interpolate.linear_windows(None, given_q, given_r, keys)
    np.testing.assert_array_equal(vq[:, keys], q[:, keys])
    np.testing.assert_array_equal(vr[:, keys], r[:, keys])
    # the first frames continue the context's motion for about 3 frames' worth of its velocity; that
    # displacement from the interpolation is blended out by the target key
    v_in, d = r[:, 9] - r[:, 8], (r[:, 50] - r[:, 9]) / 41
    for t in (10, 30, 49):
        g = 3 * -np.expm1(-(t - 9) / 3) * (1 - (t - 9) / 41) ** 2
        np.testing.assert_allclose(vr[:, t], ir[:, t] + g * (v_in - d), atol=1e-12)
    # rotations leave frame 9 turning as frames 8 -> 9 turned
    step = R.quat_angle(vq[:, 9], vq[:, 10])
    assert np.all(np.abs(step - R.quat_angle(q[:, 8], q[:, 9])) < np.abs(R.quat_angle(iq[:, 9], iq[:, 10]) - step) + 1e-9)
    # no given frame beside the gap (keys every 10): the interpolation itself
    sparse = np.arange(0, 60, 10)
    for a, b in zip(interpolate.velocity_windows(None, q, r, sparse), interpolate.linear_windows(None, q, r, sparse)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    # a very long fade is the cubic Hermite curve with one-sided velocity tangents: a line stays a line
    line = np.arange(60.0)[None, :, None] * [0.5, 0.0, -1.0]
    np.testing.assert_allclose(interpolate.velocity_windows(None, q[:1], line, keys, frames=1e9)[1][:, :51], line[:, :51], atol=1e-9)


def test_baselines_on_any_key_layout():
    rng = np.random.default_rng(2)
    q = R.quat_continuous_np(R.quat_normalize(rng.normal(size=(2, 13, 3, 4))), axis=1)
    r = rng.normal(size=(2, 13, 3))
    keys = [1, 4, 10]
    pq, pr = interpolate.linear_windows(None, q, r, keys)
    np.testing.assert_array_equal(pq[:, keys], q[:, keys])
    np.testing.assert_allclose(pr[:, 2], r[:, 1] + (r[:, 4] - r[:, 1]) / 3)
    np.testing.assert_allclose(pq[:, 7], R.quat_slerp(q[:, 4], q[:, 10], 0.5), atol=1e-12)
    np.testing.assert_array_equal(pr[:, 0], r[:, 1])  # before the first key: hold it
    np.testing.assert_array_equal(pr[:, 12], r[:, 10])  # after the last key: hold it
    zq, zr = interpolate.hold_windows(None, q, r, keys)
    np.testing.assert_array_equal(zr[:, 5:10], np.repeat(r[:, 4:5], 5, axis=1))
    np.testing.assert_array_equal(zq[:, 5:10], np.repeat(q[:, 4:5], 5, axis=1))
    np.testing.assert_array_equal(zr[:, [1, 4, 10, 11]], r[:, [1, 4, 10, 10]])


def test_score_any_key_layout(walkers):
    proto = B.lafan1([walkers], ["*_happy_*"])
    infill = B.score_keys({"i": interpolate.linear_windows, "z": interpolate.hold_windows}, proto.test, proto.stats, np.arange(0, 61, 10))
    assert 0 < infill["i"]["L2P"] < infill["z"]["L2P"]
    inbetween = B.score_keys({"i": interpolate.linear_windows}, proto.test, proto.stats, np.append(np.arange(10), 25))
    assert inbetween["i"] == B.evaluate({"i": interpolate.linear_windows}, proto.test, proto.stats, (15,))["i"][15]
    with pytest.raises(UsageError, match="key 70 is beyond the 65-frame test windows"):
        B.score_keys({"i": interpolate.linear_windows}, proto.test, proto.stats, [0, 70])


def test_lengths_the_windows_cannot_hold_are_refused(walkers):
    proto = B.lafan1([walkers], ["*_happy_*"], fold=True)
    with pytest.raises(UsageError, match="transition length 46 does not fit: .*65 frames.*1 to 45"):
        B.evaluate({"i": interpolate.linear_windows}, proto.test, proto.stats, (5, 46))


def test_split_by_patterns(walkers):
    c = load_corpus([walkers])
    train, test = B.split(c, ["*_happy_*", "*_tired_*"])
    assert len(test) == 6 and len(train) == 6
    train, test = B.split(c, ["*_happy_*"], ["*_calm_*"])
    assert {Path(f).name.split("_")[1] for f in train.files} == {"calm"}
    with pytest.raises(UsageError, match="matches both"):
        B.split(c, ["*_happy_*"], ["walk_*"])
    with pytest.raises(DataError, match="no clip matches the test pattern"):
        B.split(c, ["*_sad_*"])


def test_protocol_needs_long_enough_clips(tmp_path):
    write_corpus(tmp_path, styles=("a", "b"), clips_per_style=2, frames=(40, 60))
    with pytest.raises(DataError, match="longer than 65 frames, the protocol's test window"):
        B.lafan1([tmp_path], ["*_a_*"])


def test_methods_never_see_the_transition(walkers):
    proto = B.lafan1([walkers], ["*_happy_*"])
    seen = []

    def spy(skel, q, r, keys):
        seen.append(bool(np.isnan(q[:, 10:-1]).all() and np.isfinite(q[:, keys]).all()))
        return interpolate.linear_windows(skel, q, r, keys)

    res = B.evaluate({"spy": spy, "interpolation": interpolate.linear_windows}, proto.test, proto.stats, (5, 30))
    assert seen == [True, True]
    assert res["spy"] == res["interpolation"]
    # on smooth walks, interpolation beats holding the last frame
    zero = B.evaluate({"z": interpolate.hold_windows}, proto.test, proto.stats, (5, 30))["z"]
    assert all(zero[n]["L2P"] > res["interpolation"][n]["L2P"] for n in (5, 30))


def test_table_lists_every_method_and_the_ratios():
    res = {"interpolation": {5: {"L2Q": 0.2, "L2P": 1.0, "NPSS": 0.01}},
           "cubic": {5: {"L2Q": 0.1, "L2P": 0.5, "NPSS": 0.02}}}
    table = B.format_table(res)
    assert "cubic" in table and "relative to interpolation" in table
    last = table.splitlines()[-1].split()
    assert last[0] == "cubic" and [float(v) for v in last[1:]] == [0.5, 0.5, 2.0]


def test_cli_evaluate_json_matches_the_library(walkers, capsys):
    code = main(["evaluate", "linear", str(walkers), "--test-pattern", "*_happy_*", "--test-pattern", "*_tired_*",
                 "--lengths", "5,15", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    proto = B.lafan1([walkers], ["*_happy_*", "*_tired_*"])
    lib = B.evaluate({"interpolation": interpolate.linear_windows}, proto.test, proto.stats, (5, 15))
    assert out["results"]["interpolation"]["15"]["L2P"] == pytest.approx(lib["interpolation"][15]["L2P"], rel=1e-12)
    assert set(out["results"]) == {"interpolation", "zero-velocity"}
    assert out["test_windows"] == len(proto.test.quats)


def test_cli_evaluate_table_and_errors(walkers, capsys):
    assert main(["evaluate", "cubic", str(walkers), "--test-pattern", "*_calm_*", "--lengths", "5"]) == 0
    out = capsys.readouterr().out
    assert "cubic" in out and "zero-velocity" in out and "relative to interpolation" in out
    assert main(["evaluate", "velocity", str(walkers), "--test-pattern", "*_calm_*", "--lengths", "5", "--json"]) == 0
    assert "velocity" in json.loads(capsys.readouterr().out)["results"]
    assert main(["evaluate", "cubic", str(walkers), "--test-pattern", "*_calm_*", "--lengths", "50"]) == 2
    assert "keyfill: error: transition length 50 does not fit" in capsys.readouterr().err
    assert main(["evaluate", "nonsense", str(walkers)]) == 2
    assert "neither a method" in capsys.readouterr().err
    assert main(["evaluate", "linear", str(walkers)]) == 1  # default test split: LaFAN1's subject5
    assert "no clip matches the test pattern *subject5*" in capsys.readouterr().err


@pytest.mark.slow
def test_golden_values_from_the_bandai1_files():
    """The whole protocol from the Bandai-Namco dataset-1 BVH files reproduces the reference numbers."""
    from keyfill.learn.corpus import locate

    try:
        folder = locate("bandai1")
    except DataError as e:
        pytest.skip(str(e))
    proto = B.lafan1([folder], ["*_happy_*", "*_tired_*"], fold=True, facing_axis="+Y", cache=False)
    assert proto.info["test_windows"] == 66 and proto.info["train_windows"] == 1102
    res = B.evaluate({"zerov": interpolate.hold_windows, "interp": interpolate.linear_windows}, proto.test, proto.stats)
    names = {"quat": "L2Q", "pos": "L2P", "npss": "NPSS"}
    for key, value in json.loads(EXPECTED.read_text()).items():
        method, metric, _, n = key.replace("@", "_").split("_")
        assert res[method][int(n)][names[metric]] == pytest.approx(value, rel=1e-4), key
