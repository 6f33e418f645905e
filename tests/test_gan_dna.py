"""Motion DNA (section 3.5.1, Eqs. 11-12, Appendix D) and partial keys (section 5) of the gan method."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import fit, synthetic_corpus, tiny_config
from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import rotations as R
from keyfill.errors import ModelError, UsageError
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan.dna import dna_count
from keyfill.learn.gan.losses import dna_losses, root_free
from keyfill.learn.gan.model import complete, dna_poses, load_model
from keyfill.learn.gan.sampling import body_halves, partial_coords
from keyfill.learn.gan.task import GanTask
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_dna_losses_equal_the_hand_computed_values():
    """One joint on a line: poses x = 0..7, representative poses x = 2.5 and 10, keys 0, 3, 7, 2 frames a pose.

    Eq. 11: 2.5 is nearest frames 2 or 3 (0.5^2), 10 is nearest frame 7 (3^2): (0.25 + 9) / 2.
    Eq. 12: each frame's error to its nearest pose: 6.25 2.25 0.25 0.25 2.25 6.25 12.25 9;
    the 3 frames of [0, 3) hold 3 // 2 = 1 pose (0.25), the 4 of [3, 7) hold 2 (0.25, 2.25): 2.75 / 3.
    """
    poses = torch.zeros(1, 8, 1, 3, dtype=torch.float64)
    poses[0, :, 0, 0] = torch.arange(8.0)
    reps = torch.zeros(1, 3, 1, 3, dtype=torch.float64)
    reps[0, 0, 0, 0], reps[0, 1, 0, 0], reps[0, 2, 0, 0] = 2.5, 10.0, -50.0
    valid = torch.tensor([[True, True, False]])  # the third is padding and must not count
    keys = torch.zeros(1, 8, dtype=torch.bool)
    keys[0, [0, 3, 7]] = True
    l1, l2 = dna_losses(poses, reps, valid, keys, min_frames=2)
    assert float(l1) == pytest.approx((0.25 + 9) / 2) and float(l2) == pytest.approx(2.75 / 3)
    e1, e2 = dna_losses(poses, reps, valid, keys, min_frames=2, squared=False)
    assert float(e1) == pytest.approx((0.5 + 3) / 2) and float(e2) == pytest.approx((0.5 + 0.5 + 1.5) / 3)
    # no interval as long as min_frames: Eq. 12 has no terms
    assert float(dna_losses(poses, reps, valid, keys, min_frames=5)[1]) == 0.0


def test_root_free_poses_ignore_the_root_rotation():
    g = torch.Generator().manual_seed(0)
    rel = torch.randn(2, 5, 4, 3, generator=g, dtype=torch.float64)
    rel[:, :, 0] = 0
    quats = torch.zeros(2, 5, 4, 4, dtype=torch.float64)
    quats[..., 0] = 1
    turn = torch.as_tensor(R.quat_from_rotvec(np.array([0.3, -1.1, 0.4])))
    turned = R.quat_rotate(turn.expand(2, 5, 4, 4), rel)
    tq = quats.clone()
    tq[:, :, 0] = turn
    assert torch.allclose(root_free(quats, rel), rel[:, :, 1:])
    assert torch.allclose(root_free(tq, turned), rel[:, :, 1:])


def test_appendix_d_one_pose_per_three_seconds_of_gap():
    assert dna_count([0, 89, 300, 480], fps=30) == 0 + 2 + 2
    assert dna_count([0, 10], fps=30) == 1


def test_partial_key_sampling_gives_root_half_body_and_planes():
    from keyfill.learn.corpus import fold_root

    sk = walker_skeleton()
    m = walker_motion(sk, 10, np.random.default_rng(0))
    _q, p = fold_root(m.rotations, m.positions, sk.parents)
    halves = body_halves(sk.replace(offsets=np.vstack([np.zeros(3), p[0, 1:]])))
    names = [[sk.names[j] for j in np.flatnonzero(h)] for h in halves]
    assert names == [["joint_Root", "Hips", "Spine", "Head"], ["joint_Root", "Hips", "Leg_L", "Foot_L", "Leg_R",
                                                                "Foot_R"]]
    rng = np.random.default_rng(0)
    kinds = set()
    for _ in range(60):
        c = partial_coords(rng, 3, sk.num_joints, halves, 0.75)
        assert c[:, 0].any()  # the root is always given (its position, or two coordinates of it)
        kinds.add("full" if c.all() else "root" if not c[:, 1:].any() else "plane" if (~c).all(axis=(0, 1)).any()
                  else "half")
    assert kinds == {"full", "root", "plane", "half"}


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """``(DNA + partial-key model, plain model)`` folders trained for a handful of steps."""
    root = tmp_path_factory.mktemp("gan_dna")
    corpus = synthetic_corpus(root / "clips", clips_per_style=2)
    cfg = tiny_config(max_frames=256, steps_per_epoch=3, style_dim=4, dna_width=8, partial_keys=True)
    path_dir = fit(GanTask(corpus, cfg, "path", epochs=1), root / "path").model
    task = GanTask(corpus, cfg, "generator", path_model=path_dir, epochs=1)
    out = fit(task, root / "dna")
    plain = tiny_config(max_frames=256, steps_per_epoch=2)
    plain_path = fit(GanTask(corpus, plain, "path", epochs=1), root / "plain_path").model
    plain_dir = fit(GanTask(corpus, plain, "generator", path_model=plain_path, epochs=1), root / "plain").model
    return out, plain_dir


@pytest.fixture(scope="module")
def motion():
    return walker_motion(walker_skeleton(), 240, np.random.default_rng(42))


KEYS = Keys(np.array([0, 50, 130, 200]))


def test_training_logs_the_dna_losses_and_errors(models):
    out, _ = models
    model = load_model(out.model)
    assert model.config.dna and model.bank is not None and len(model.bank) > 0
    assert model.bank.poses.shape[1:] == (model.skeleton.num_joints - 1, 3)
    row = out.history[-1]
    assert {"loss_dna_1", "loss_dna_2", "dna_error_1", "key_root_error"} <= set(row)
    assert np.isfinite(row["loss_dna_1"]) and row["dna_error_1"] > 0


def test_two_dnas_give_different_motions_through_identical_keys(models, motion, tmp_path):
    from keyfill import io

    model = str(models[0].model)
    other = walker_motion(walker_skeleton(), 200, np.random.default_rng(7))
    rest_pose = other.replace(rotations=R.quat_mul(R.quat_from_rotvec(
        np.random.default_rng(3).normal(size=(200, other.num_joints, 3)) * 0.6), other.rotations))
    io.save(other, tmp_path / "a.bvh")
    io.save(rest_pose, tmp_path / "b.bvh")
    a = complete(motion, KEYS, CompleteOptions(model=model, seed=1, dna=str(tmp_path / "a.bvh"))).motion
    b = complete(motion, KEYS, CompleteOptions(model=model, seed=1, dna=str(tmp_path / "b.bvh"))).motion
    k = KEYS.frames
    assert np.array_equal(a.rotations[k], b.rotations[k]) and np.array_equal(a.positions[k], b.positions[k])
    between = np.setdiff1d(np.arange(k[0], k[-1]), k)
    assert np.abs(a.rotations[between] - b.rotations[between]).max() > 1e-4
    listed = complete(motion, KEYS, CompleteOptions(model=model, seed=1, dna=f"{tmp_path / 'b.bvh'}:3,40,90")).info
    assert listed["dna_poses"] == 3
    bank = complete(motion, KEYS, CompleteOptions(model=model, seed=1, dna_count=2)).info
    assert bank["dna_poses"] == 2


def test_bad_dna_sources(models, motion, tmp_path):
    from keyfill import io

    model = str(models[0].model)
    io.save(walker_motion(walker_skeleton(leg_length=55.0), 50, np.random.default_rng(1)), tmp_path / "long.bvh")
    io.save(walker_motion(walker_skeleton(), 50, np.random.default_rng(1)), tmp_path / "ok.bvh")
    with pytest.raises(ModelError, match="DNA motion has another skeleton"):
        complete(motion, KEYS, CompleteOptions(model=model, dna=str(tmp_path / "long.bvh")))
    with pytest.raises(UsageError, match="DNA frame 50 is outside"):
        complete(motion, KEYS, CompleteOptions(model=model, dna=f"{tmp_path / 'ok.bvh'}:3,50"))
    with pytest.raises(UsageError, match="no Motion DNA encoder"):
        complete(motion, KEYS, CompleteOptions(model=str(models[1]), dna=str(tmp_path / "ok.bvh")))
    with pytest.raises(UsageError, match="^count must be between 1 and 256, got 0"):
        dna_poses(load_model(model), count=0)  # the test model fills at most 256 frames at once


@pytest.mark.parametrize("joints,given", [(["Hips"], "position"), (["Hips", "Leg_L", "Foot_L", "Leg_R", "Foot_R"],
                                                                    "pose"), (None, "XY")])
def test_partial_keys_root_half_body_and_2d(models, motion, joints, given):
    keys = KEYS.restrict(motion.skeleton, joints, given)
    out = complete(motion, keys, CompleteOptions(model=str(models[0].model), seed=2))
    m = out.motion
    assert np.all(np.isfinite(m.rotations)) and out.info["partial_keys"].startswith(given)
    rot_mask, pos_mask = keys.channel_masks(motion.skeleton)
    k = keys.frames
    assert np.array_equal(m.positions[k][pos_mask], motion.positions[k][pos_mask])
    assert np.array_equal(m.rotations[k][rot_mask], motion.rotations[k][rot_mask])


def test_partial_keys_need_a_partial_key_model(models, motion):
    keys = KEYS.restrict(motion.skeleton, ["Hips"], "position")
    with pytest.raises(UsageError, match="trained on whole poses only"):
        complete(motion, keys, CompleteOptions(model=str(models[1])))
    with pytest.raises(UsageError, match="root's position at one key"):
        complete(motion, KEYS.restrict(motion.skeleton, ["Spine"]), CompleteOptions(model=str(models[0].model)))


def test_command_line_dna_partial_keys_and_bad_input(models, motion, tmp_path, capsys):
    from keyfill import io
    from keyfill.cli.main import main

    model = str(models[0].model)
    io.save(motion, tmp_path / "walk.bvh")
    io.save(walker_motion(walker_skeleton(), 120, np.random.default_rng(9)), tmp_path / "dna.bvh")
    io.save(walker_motion(walker_skeleton(leg_length=55.0), 60, np.random.default_rng(1)), tmp_path / "tall.bvh")
    src = ["complete", str(tmp_path / "walk.bvh"), "--keys", "0,50,130,200"]
    base = src + ["--method", "gan", "--model", model]
    capsys.readouterr()
    assert main(base + ["-o", str(tmp_path / "a.bvh"), "--dna", str(tmp_path / "dna.bvh"), "--dna-count", "3"]) == 0
    assert main(base + ["-o", str(tmp_path / "b.bvh"), "--key-joints", "Hips", "--key-positions"]) == 0
    assert main(base + ["-o", str(tmp_path / "c.bvh"), "--key-plane", "XY", "--dna", f"{tmp_path / 'dna.bvh'}:5,60"]) == 0
    assert io.load(tmp_path / "a.bvh").num_frames == 240
    capsys.readouterr()
    bad = [
        (["--dna", str(tmp_path / "tall.bvh")], 1, "another skeleton"),
        (["--dna", f"{tmp_path / 'dna.bvh'}:5,120"], 2, "DNA frame 120 is outside"),
        (["--key-joints", "Tail"], 2, "unknown joint 'Tail'"),
        (["--key-plane", "XW"], 2, "view plane"),
    ]
    cubic = [(src + ["--method", "cubic", "--key-joints", "Hips"], 2, "accepted by: gan"),
             (src + ["--method", "cubic", "--dna", str(tmp_path / "dna.bvh")], 2, "apply to methods with Motion DNA")]
    for args, code, text in [(base + extra, code, text) for extra, code, text in bad] + cubic:
        args = args + ["-o", str(tmp_path / "bad.bvh")]
        assert main(args) == code, (args, capsys.readouterr().err)
        out = capsys.readouterr()
        assert out.out == "" and out.err.startswith("keyfill: error:") and text in out.err
        assert len(out.err.strip().splitlines()) == 1
        assert not (tmp_path / "bad.bvh").exists()


def test_quality_report_of_a_tiny_model(models):
    """The figures of docs/gan.md come out of a model: all finite, in cm, for every kind of key."""
    from keyfill.learn.corpus import load_corpus
    from keyfill.learn.gan.quality import quality_report

    model = load_model(models[0].model)
    clips_dir = models[0].model.parent / "clips"
    corpus = load_corpus([clips_dir], cache=False)
    report = quality_report(model, corpus, range(len(corpus)), sequences=2, frames=200, seed=0)
    assert set(report["key_errors"]) == {"full", "root", "half", "plane", "sketch"}
    assert report["key_errors"]["root"]["joints_cm"] is None  # root-only keys give no joint
    assert all(np.isfinite(v["root_cm"]) for v in report["key_errors"].values())
    assert all(np.isfinite(report["key_errors"][k]["joints_cm"]) for k in ("full", "half", "plane", "sketch"))
    # a sketch's keys are the plane keys' with stretched bones, scored against the true poses
    assert report["key_errors"]["sketch"]["joints_cm"] != report["key_errors"]["plane"]["joints_cm"]
    assert report["dna_error_1_cm"] > 0 and report["variety_cm"]["dnas"] > 0 and report["variety_cm"]["seeds"] > 0
    assert report["dna_pull_cm"]["own"] > 0 and report["dna_pull_cm"]["other"] > 0


def test_benchmark_windows_of_a_dna_model_draw_their_dna_from_the_bank(models, motion):
    from keyfill.learn.corpus import fold_root

    model = load_model(models[0].model)
    q, p = fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    keys = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 40])
    quats, root = q[None, :65], p[None, :65, 0]
    a = model.benchmark_method(seed=0)(model.skeleton, quats, root, keys)
    b = model.benchmark_method(seed=0)(model.skeleton, quats, root, keys)
    assert np.array_equal(a[0], b[0]) and np.allclose(a[0][:, keys], quats[:, keys])


def test_a_model_folder_from_before_motion_dna_loads_and_completes_as_before(models, motion, tmp_path):
    """config.json of a model written before the DNA and partial-key settings existed: the defaults apply."""
    import json
    import shutil

    old = tmp_path / "old"
    shutil.copytree(models[1], old)
    config = json.loads((old / "config.json").read_text())
    for name in ("dna_width", "dna_weight", "dna_seconds", "partial_keys", "partial_fraction"):
        del config["gan"][name]
    (old / "config.json").write_text(json.dumps(config))
    a = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=4)).motion
    b = complete(motion, KEYS, CompleteOptions(model=str(old), seed=4)).motion
    assert np.array_equal(a.rotations, b.rotations) and np.array_equal(a.positions, b.positions)


def test_training_sequences_draw_one_dna_pose_per_three_seconds_of_gap(models):
    from keyfill.learn.corpus import load_corpus
    from keyfill.learn.gan.dna import build_bank
    from keyfill.learn.gan.poses import clip_pool
    from keyfill.learn.gan.sampling import training_sequence

    model = load_model(models[0].model)
    corpus = load_corpus([models[0].model.parent / "clips"], cache=False)
    cfg = model.config
    pool, bank = clip_pool(corpus), build_bank(corpus, range(len(corpus)))
    rng = np.random.default_rng(0)
    for _ in range(5):
        seq = training_sequence(pool, rng, cfg, [], bank)
        keys = np.flatnonzero(seq["key_mask"])
        assert len(seq["dna"]) == dna_count(keys, corpus.fps, cfg.dna_seconds)
        J = corpus.skeleton.num_joints
        mask = seq["dense"][3 * J :]  # the sparse format's 0/1 mask: 1 only at key frames
        assert set(np.unique(mask)) <= {0.0, 1.0} and not mask[:, np.setdiff1d(np.arange(mask.shape[1]), keys)].any()
