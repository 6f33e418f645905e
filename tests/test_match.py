"""The motion library (keyfill.learn.library), --method match and the guard, on small libraries of the Mixamo
fixture and variants of it (retimed, arms swung), so no shared data is needed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, one_error_line, run

from keyfill import interpolate, io
from keyfill import rotations as R
from keyfill.errors import ModelError, UsageError
from keyfill.learn import registry
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.library import store
from keyfill.learn.library.features import describe
from keyfill.learn.library.index import POSE_INDEX, THRESHOLD, PoseIndex, library_index, load_pose_index
from keyfill.learn.library.matcher import Matcher, MatchSettings
from keyfill.motion import Keys, Motion

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"


def clip() -> Motion:
    return io.load(MIXAMO).replace(keys=None)


def variant(m: Motion, swing: float, speed: float) -> Motion:
    """Another motion of the same rig: the clip played ``speed`` times as fast, its arms swung by ``swing``
    radians about the side axis, in and out of phase."""
    t = np.arange(0, m.num_frames - 1, speed)
    rot, pos = interpolate.at_times(R.quat_continuous_np(m.rotations, axis=0), m.positions, t)
    phase = np.sin(np.linspace(0, 4 * np.pi, len(t)))
    for name, sign in (("mixamorig:LeftArm", 1.0), ("mixamorig:RightArm", -1.0), ("mixamorig:Spine1", 0.5)):
        j = m.skeleton.index(name)
        turn = R.quat_from_rotvec(np.outer(sign * swing * phase, [1.0, 0.0, 0.0]))
        rot[:, j] = R.quat_mul(rot[:, j], turn)
    return Motion(m.skeleton, m.fps, rot, pos)


def write_clips(folder: Path) -> list[Path]:
    """The test walk and three variants of it as BVH files in ``folder`` (a library's or a corpus's clips)."""
    m = clip()
    paths = [folder / "a_walk.bvh"]
    io.save(m, paths[0])
    for n, (swing, speed) in enumerate([(0.15, 0.95), (0.25, 1.05), (0.35, 1.0)]):
        paths.append(folder / f"b_variant_{n}.bvh")
        io.save(variant(m, swing, speed), paths[-1])
    return paths


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    return write_clips(tmp_path_factory.mktemp("clips"))


@pytest.fixture(scope="module")
def library(clips, tmp_path_factory):
    out = tmp_path_factory.mktemp("lib") / "lib"
    store.build(clips, out)
    return out


def world(m: Motion) -> np.ndarray:
    return m.world_positions()


def test_a_gap_cut_from_a_library_clip_comes_back_as_that_clip_with_the_keys_exact(library):
    m = clip()
    keys = Keys([0, 20, 40, 60])
    matcher = Matcher(store.load(library))
    filled, report = matcher.fill(m, keys, 0, MatchSettings(standing=False))
    assert all(g["filled_by"] == "match" and g["source"]["clip"] == "a_walk.bvh" for g in report)
    assert [g["source"]["frames"] for g in report] == [[0, 20], [20, 40], [40, 60]]
    height = np.ptp(world(m)[0][:, 1])
    assert np.abs(world(filled)[:61] - world(m)[:61]).max() <= 1e-6 * height
    done = registry.complete(m, keys, "match", CompleteOptions(library=str(library), feet="free", guard="off"))
    k = keys.frames
    assert np.array_equal(done.motion.rotations[k], m.rotations[k])
    assert np.array_equal(done.motion.positions[k], m.positions[k])


def test_seams_are_continuous_in_position_and_velocity(library):
    m = variant(clip(), 0.75, 1.05)  # a motion the library holds only in pieces
    keys = Keys([0, 16, 32, 48, 63])
    filled, report = Matcher(store.load(library)).fill(m, keys, 2, MatchSettings(standing=False))
    assert sum(g["filled_by"] == "match" for g in report) == 4
    p = world(filled)
    accel = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1).max(axis=-1)  # (F - 2,) frames 1 .. F-2
    inner = keys.frames[1:-1]
    elsewhere = np.delete(accel, inner - 1)
    # a jump of velocity at a key would be an acceleration spike there; the cross-fade leaves none
    assert accel[inner - 1].max() <= 1.5 * np.percentile(elsewhere, 95)
    jumps = np.linalg.norm(np.diff(p, axis=0), axis=-1).max(axis=-1)
    assert jumps.max() <= 3 * np.median(jumps) + 1e-9  # no step in position anywhere


def test_seed_zero_is_repeatable_and_other_seeds_differ(library, tmp_path):
    m = variant(clip(), 0.2, 1.0)
    keys = Keys([0, 22, 44, 65])
    options = {s: CompleteOptions(library=str(library), seed=s, guard="off") for s in (0, 1, 2)}
    paths = {}
    for name, s in (("a", 0), ("b", 0), ("c", 1), ("d", 2)):
        paths[name] = tmp_path / f"{name}.bvh"
        io.save(registry.complete(m, keys, "match", options[s]).motion, paths[name])
    assert paths["a"].read_bytes() == paths["b"].read_bytes()
    assert paths["c"].read_bytes() != paths["d"].read_bytes()
    c, d = (world(io.load(paths[n])) for n in "cd")
    assert np.abs(c - d).max() > 1.0  # visibly different motion (centimetres here)


def test_the_guard_fires_on_unfamiliar_poses_and_never_on_library_poses(library):
    lib = store.load(library)
    index = library_index(lib)
    assert index.familiarity(np.asarray(lib.features, dtype=np.float32)).max() < THRESHOLD
    m = clip()
    sk = m.skeleton
    upside = m.frames([10]).rotations.copy()
    hips = sk.index("mixamorig:Hips")
    upside[0, hips] = R.quat_mul(R.quat_from_rotvec(np.array([np.pi, 0.0, 0.0])), upside[0, hips])
    bent = m.frames([10]).rotations.copy()
    for name in ("mixamorig:LeftLeg", "mixamorig:RightLeg"):  # knees bent the wrong way, 100 degrees
        j = sk.index(name)
        bent[0, j] = R.quat_mul(bent[0, j], R.quat_from_rotvec(np.array([-np.radians(100), 0.0, 0.0])))
    odd = Motion(sk, m.fps, np.concatenate([upside, bent]), m.positions[[10, 10]])
    scores = index.familiarity(describe(odd.world_positions(), lib.frames)[0])
    assert (scores > THRESHOLD).all(), scores


def test_the_guard_falls_back_to_cubic_in_unfamiliar_gaps_and_says_so(library):
    m = clip()
    sk = m.skeleton
    rot = m.rotations.copy()
    hips = sk.index("mixamorig:Hips")
    rot[30:, hips] = R.quat_mul(R.quat_from_rotvec(np.array([np.pi, 0.0, 0.0])), rot[30:, hips])  # upside down
    odd = m.replace(rotations=rot)
    keys = Keys([0, 15, 30, 45, 60])
    done = registry.complete(odd, keys, "match", CompleteOptions(library=str(library), feet="free"))
    block = done.info["guard"]
    assert block["mode"] == "fallback" and block["unfamiliar"] >= 2
    flags = [g["unfamiliar"] for g in block["gaps"]]
    assert flags[:1] == [False] and flags[2:] == [True, True]
    spline = interpolate.cubic(odd, keys)
    assert np.allclose(done.motion.rotations[31:45], spline.rotations[31:45])
    warned = registry.complete(odd, keys, "match", CompleteOptions(library=str(library), feet="free", guard="warn"))
    assert warned.info["guard"]["filled_by_cubic"] == 0
    assert not np.allclose(warned.motion.rotations[31:45], spline.rotations[31:45])


def test_a_rebuild_reads_only_new_or_changed_clips(clips, tmp_path):
    folder = tmp_path / "clips"
    folder.mkdir()
    for p in clips[:3]:
        shutil.copy(p, folder / p.name)
    first = store.build([folder], tmp_path / "lib")
    assert (first["added"], first["reused"], first["removed"]) == (3, 0, 0)
    (tmp_path / "lib" / "LICENSE").write_text("the clips' licence")
    again = store.build([folder], tmp_path / "lib")
    assert (again["added"], again["reused"], again["removed"]) == (0, 3, 0)
    assert (tmp_path / "lib" / "LICENSE").read_text() == "the clips' licence"  # the folder's other files stay
    shutil.copy(clips[3], folder / clips[2].name)  # one clip's bytes change
    changed = store.build([folder], tmp_path / "lib")
    assert (changed["added"], changed["reused"], changed["removed"]) == (1, 2, 1)
    lib = store.load(tmp_path / "lib")
    assert [c.name for c in lib.clips] == sorted(p.name for p in folder.iterdir())


def test_a_gap_longer_than_every_library_clip_is_cubic_and_reported(library):
    m = clip()
    long = Motion(m.skeleton, m.fps, np.concatenate([m.rotations] * 3), np.concatenate([m.positions] * 3))
    keys = Keys([0, 10, 150, 160])
    _, report = Matcher(store.load(library)).fill(long, keys, 0, MatchSettings(standing=False))
    assert report[1]["filled_by"] == "cubic" and "long enough" in report[1]["why"]


def _copy(library, tmp_path):
    target = tmp_path / "lib"
    shutil.copytree(library, target)
    return target


def test_a_saved_pose_index_keeps_its_axes_and_scores_as_one_computed_at_load(library, tmp_path):
    """A model folder's pose_index.npz holds the tree's axes (saving the SVD at every start-up, issue 44): the
    loaded index scores exactly as one whose axes are computed from its features, a file of the older three
    fields still loads, and axes of the wrong shape are refused."""
    lib = store.load(library)
    poses = np.asarray(lib.features, dtype=np.float32)
    library_index(lib).save(tmp_path)
    saved = load_pose_index(tmp_path, "saved")
    assert saved.stored_axes is not None
    computed = PoseIndex(saved.features, saved.spread, saved.threshold, "computed")
    for got, want in zip(saved.axes(), computed.axes()):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    queries = poses[::7] + np.float32(0.01)
    assert np.array_equal(saved.familiarity(queries), computed.familiarity(queries))
    with np.load(tmp_path / POSE_INDEX) as z:
        fields = {k: z[k] for k in z.files}
    np.savez_compressed(tmp_path / POSE_INDEX, **{k: fields[k] for k in ("features", "spread", "threshold")})
    old = load_pose_index(tmp_path, "old")
    assert old.stored_axes is None and np.array_equal(old.familiarity(queries), computed.familiarity(queries))
    np.savez(tmp_path / POSE_INDEX, **{**fields, "basis": fields["basis"][:, :3]})
    with pytest.raises(ModelError, match="damaged pose index \\(axes"):
        load_pose_index(tmp_path, "bad")
    features = fields["features"].copy()
    features[3, 5] = np.inf
    np.savez(tmp_path / POSE_INDEX, **{**fields, "features": features})
    with pytest.raises(ModelError, match="damaged pose index \\(features that are not finite"):
        load_pose_index(tmp_path, "bad")


def test_damaged_libraries_are_refused_with_what_is_wrong(library, tmp_path):
    lib = _copy(library, tmp_path)
    data = bytearray((lib / "rotations.npy").read_bytes())
    data[-5] ^= 0x40
    (lib / "rotations.npy").write_bytes(bytes(data))
    with pytest.raises(ModelError, match="has changed since the library was built"):
        store.load(lib)
    shutil.rmtree(lib)
    lib = _copy(library, tmp_path)
    (lib / "features.npy").write_bytes((lib / "features.npy").read_bytes()[:200])
    with pytest.raises(ModelError, match="features.npy"):
        store.load(lib)
    shutil.rmtree(lib)
    lib = _copy(library, tmp_path)
    np.save(lib / "heading.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)  # a pickle: never loaded
    with pytest.raises(ModelError, match="heading.npy"):
        store.load(lib)
    shutil.rmtree(lib)
    lib = _copy(library, tmp_path)
    np.save(lib / "hips.npy", np.zeros((3, 3), dtype=np.float64))
    with pytest.raises(ModelError, match="hips.npy is float64"):
        store.load(lib)
    shutil.rmtree(lib)
    lib = _copy(library, tmp_path)
    manifest = json.loads((lib / "library.json").read_text())
    (lib / "library.json").write_text(json.dumps({**manifest, "clips": []}))
    with pytest.raises(ModelError, match="no clips"):
        store.load(lib)


def test_cli_builds_describes_and_matches(clips, tmp_path, capsys):
    code, out, err = run(capsys, "library", "build", *clips, "-o", tmp_path / "lib", "--json")
    assert code == 0, err
    assert json.loads(out)["clips"] == 4
    code, out, err = run(capsys, "library", "info", tmp_path / "lib")
    assert code == 0 and "4 clips" in out
    code, out, err = run(capsys, "complete", clips[1], "--key-every", "20", "--method", "match", "--library",
                         tmp_path / "lib", "-o", tmp_path / "out.bvh", "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["method"] == "match" and info["model"] == "lib" and info["feet"] == "lock"
    assert len(info["gaps"]) == len(info["keys"]) - 1 == info["guard"]["gaps_scored"]


def test_cli_bad_input_is_one_line_and_writes_nothing(library, clips, tmp_path, capsys):
    out = tmp_path / "out.bvh"
    code, _, err = run(capsys, "complete", clips[0], "--key-every", "20", "--library", library, "-o", out)
    assert code == 2 and "--library applies to methods that match from a motion library" in one_error_line(err)
    code, _, err = run(capsys, "complete", clips[0], "--key-every", "20", "--method", "cubic", "--guard", "warn",
                       "-o", out)
    assert code == 2 and "--guard applies to the human methods" in one_error_line(err)
    code, _, err = run(capsys, "complete", clips[0], "--key-every", "20", "--method", "match", "--library", tmp_path,
                       "-o", out)
    assert code == 1 and "not a keyfill library" in one_error_line(err)
    lamp = DATA.parent.parent / "examples" / "lamp" / "keys.usda"
    code, _, err = run(capsys, "complete", lamp, "--method", "match", "--library", library, "-o", out)
    assert code == 1 and "another skeleton than the model" in one_error_line(err)
    code, _, err = run(capsys, "library", "build", lamp, "-o", tmp_path / "lamp-lib")
    assert code == 1 and "library's skeleton" in one_error_line(err)
    assert not out.exists() and not (tmp_path / "lamp-lib").exists()


def test_the_lafan1_protocol_scores_match_and_a_library_clip_comes_back_exactly(library, clips):
    from keyfill.learn.match.model import load
    from keyfill.learn.protocols import lafan1

    proto = lafan1.lafan1([c for c in clips], ["a_walk*"], None, fold=False)
    method = load(library).benchmark_method()
    assert method.folded is False  # the Mixamo hips are the root
    scores = lafan1.evaluate({"match": method, "linear": lafan1.resolve_method("linear")[1]}, proto.test,
                             proto.stats, lengths=(15, 30))
    for n in (15, 30):
        assert scores["match"][n]["L2P"] < 1e-4 < scores["linear"][n]["L2P"]


def test_a_root_path_is_walked_with_its_spots_exact(library):
    m = clip()
    keys = Keys([0, 30, 60]).restrict(m.skeleton, ["mixamorig:Hips"], "position")
    options = CompleteOptions(library=str(library), guard="off")
    done = registry.complete(m, keys, "match", options)
    hips = m.skeleton.index("mixamorig:Hips")
    k = keys.frames
    assert np.array_equal(done.motion.positions[k, hips], m.positions[k, hips])
    assert [g["filled_by"] for g in done.info["gaps"]] == ["match", "match"]
    hands = Keys([0, 30, 60]).restrict(m.skeleton, ["mixamorig:LeftHand"], "position")
    with pytest.raises(UsageError, match="root path"):
        registry.complete(m, hands, "match", options)


def test_the_tree_finds_the_same_neighbours_by_brute_force_and_by_scipy(monkeypatch):
    """A few queries are answered without scipy (every point compared), many through the cKDTree: the
    same neighbours, nearest first."""
    from keyfill.learn.library import index as I

    rng = np.random.default_rng(3)
    feats = rng.normal(size=(5000, 30)).astype(np.float32)
    mean, basis = I.principal_axes(feats, 8)
    queries = feats[rng.integers(0, 5000, 40)] + rng.normal(scale=0.05, size=(40, 30)).astype(np.float32)
    brute = I.Tree(feats, mean, basis)
    by_brute = brute.query(queries, 32)
    assert brute.tree is None  # 40 x 5000 pairs: no tree built
    monkeypatch.setattr(I, "BRUTE_FORCE_PAIRS", 0)
    tree = I.Tree(feats, mean, basis)
    by_tree = tree.query(queries, 32)
    assert tree.tree is not None
    assert np.array_equal(by_brute, by_tree)


def test_the_fallback_is_the_whole_spline_made_gap_by_gap():
    """fall_back makes only the unfamiliar gaps' pieces of the cubic spline (from the keys around each): the
    same bits as the spline through every key, whichever gaps (the first and last included), in a copy or in
    the output's own arrays."""
    from test_long_takes import long_motion

    from keyfill.learn.library.guard import fall_back

    motion = long_motion(600, seed=4)
    keys = Keys(np.array([0, 17, 50, 61, 130, 200, 290, 333, 400, 470, 599]))
    spline = interpolate.cubic(motion, keys)
    rng = np.random.default_rng(1)
    for _ in range(4):
        unfamiliar = rng.random(len(keys.frames) - 1) < 0.5
        unfamiliar[[0, -1]] = True
        out = fall_back(motion, motion, keys, unfamiliar)
        for g, (a, b) in enumerate(zip(keys.frames[:-1], keys.frames[1:])):
            source = spline if unfamiliar[g] else motion
            assert np.array_equal(out.rotations[a + 1: b], source.rotations[a + 1: b])
            assert np.array_equal(out.positions[a + 1: b], source.positions[a + 1: b])
        own = motion.replace(rotations=motion.rotations.copy(), positions=motion.positions.copy())
        kept = fall_back(own, motion, keys, unfamiliar, in_place=True)  # a long take's: no copy
        assert kept.rotations is own.rotations and np.array_equal(kept.rotations, out.rotations)
        assert np.array_equal(kept.positions, out.positions)
