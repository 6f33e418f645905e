"""Issue 29's command line: ``keyfill retarget``, ``keyfill info --rig`` and ``keyfill complete --rig-map``."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, run, shared_path

from keyfill import io
from keyfill.characters.retarget import make_rig
from keyfill.learn.rig_bridge import mapped_joints

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
LAMP = Path(__file__).parent.parent / "examples" / "lamp" / "keys.usda"
GRIP = "mixamorig:L_Grip"  # a name the mapper reads as no hand


def one_error(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("keyfill: error: "), err
    assert "Traceback" not in err and "internal error" not in err
    return lines[0].removeprefix("keyfill: error: ")


def renamed_mixamo(tmp_path) -> Path:
    """The Mixamo fixture with its left hand renamed so that no name says hand (its fingers keep theirs)."""
    text = MIXAMO.read_text()
    text, n = re.subn(r"(JOINT\s+)mixamorig:LeftHand(\s*\n)", rf"\g<1>{GRIP}\g<2>", text)
    assert n == 1
    path = tmp_path / "grip.bvh"
    path.write_text(text)
    return path


def toml(tmp_path, text: str, name: str = "map.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def mapped_world(motion) -> np.ndarray:
    return motion.world_positions()[:, mapped_joints(make_rig(motion.skeleton))]


# --- keyfill retarget -------------------------------------------------------------------


def test_retarget_mixamo_onto_cmu_and_back(capsys, tmp_path):
    source, rig = io.load(MIXAMO), io.load(CMU)
    onto = tmp_path / "cmu_walk.bvh"
    code, out, err = run(capsys, "retarget", MIXAMO, "--to", CMU, "-o", onto, "--json")
    assert code == 0, err
    moved = io.load(onto)
    assert moved.skeleton.names == rig.skeleton.names
    assert moved.skeleton.channels == rig.skeleton.channels and moved.skeleton.euler_orders == rig.skeleton.euler_orders
    np.testing.assert_allclose(moved.skeleton.offsets, rig.skeleton.offsets, atol=1e-6)
    assert moved.num_frames == source.num_frames == 69 and moved.fps == source.fps == 30.0  # CMU's file is 120 fps
    report = json.loads(out)
    assert report["input"] == str(MIXAMO) and report["output"] == str(onto) and report["rig"] == str(CMU)
    assert (report["frames"], report["fps"], report["joints"]) == (69, 30.0, rig.num_joints)
    assert report["source_rig"]["upper_arm_l"] == "mixamorig:LeftArm"
    assert report["target_rig"]["spine"] == ["LowerBack", "Spine", "Spine1"]
    assert report["hip_scale"] == pytest.approx(make_rig(rig.skeleton).hip_height / make_rig(source.skeleton).hip_height)
    assert 0.1 < report["hip_scale"] < 0.3  # CMU's rig is about 24 units tall, Mixamo's 176
    # the hips' path, scaled (both rigs are Y-up, their hips are their top joints)
    np.testing.assert_allclose(moved.world_positions()[:, 0], source.world_positions()[:, 0] * report["hip_scale"],
                               atol=1e-5)

    back = tmp_path / "mixamo_again.bvh"
    code, _, err = run(capsys, "retarget", onto, "--to", MIXAMO, "-o", back)
    assert code == 0, err
    again = io.load(back)
    assert again.skeleton.names == source.skeleton.names and again.skeleton.channels == source.skeleton.channels
    assert again.num_frames == 69 and again.fps == 30.0
    height = np.ptp(source.world_positions()[0], axis=0).max()
    # bone directions of mapped joints carry over exactly, so the round trip gives their places back
    assert np.abs(mapped_world(again) - mapped_world(source)).max() < 1e-6 * height
    assert "wrote" in err and str(back) in err


def test_retarget_to_usd_and_the_rig_frames_do_not_matter(capsys, tmp_path):
    posed = io.load(CMU)
    stood = tmp_path / "rig.bvh"  # the same skeleton, frame 0 turned: the reference pose comes from the offsets
    io.save(posed.replace(rotations=posed.rotations[::-1].copy()), stood)
    a, b = tmp_path / "a.usda", tmp_path / "b.usda"
    assert run(capsys, "retarget", MIXAMO, "--to", CMU, "-o", a)[0] == 0
    assert run(capsys, "retarget", MIXAMO, "--to", stood, "-o", b)[0] == 0
    ma, mb = io.load(a), io.load(b)
    assert ma.skeleton.names == posed.skeleton.names and ma.num_frames == 69 and ma.fps == 30.0
    np.testing.assert_allclose(ma.world_positions(), mb.world_positions(), atol=1e-6)


def test_retarget_a_folder(capsys, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "mixamo.bvh").write_bytes(MIXAMO.read_bytes())
    (folder / "cmu.bvh").write_bytes(CMU.read_bytes())
    code, out, err = run(capsys, "retarget", folder, "--to", MIXAMO, "-o", tmp_path / "out/", "--format", "usda",
                         "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert (summary["inputs"], summary["done"], summary["failed"]) == (2, 2, 0)
    by_name = {Path(f["input"]).name: f for f in summary["files"]}
    assert by_name["cmu.bvh"]["output"] == str(tmp_path / "out" / "cmu.usda")
    assert (by_name["cmu.bvh"]["frames"], by_name["cmu.bvh"]["fps"]) == (4, 120.0)
    assert by_name["cmu.bvh"]["source_rig"]["hips"] == "Hips"
    names = io.load(MIXAMO).skeleton.names
    for stem, frames, fps in (("cmu", 4, 120.0), ("mixamo", 69, 30.0)):
        m = io.load(tmp_path / "out" / f"{stem}.usda")
        assert m.skeleton.names == names and (m.num_frames, m.fps) == (frames, fps)
    # a second run skips both; a lamp among them fails alone, naming itself
    (folder / "lamp.usda").write_bytes(LAMP.read_bytes())
    code, out, err = run(capsys, "retarget", folder, "--to", MIXAMO, "-o", tmp_path / "out/", "--format", "usda",
                         "--json")
    assert code == 1
    summary = json.loads(out)
    assert (summary["done"], summary["skipped"], summary["failed"]) == (0, 2, 1)
    line = one_error(err)
    assert line.startswith(f"{folder / 'lamp.usda'}: ") and "hips" in line and "--rig-map" in line
    assert not (tmp_path / "out" / "lamp.usda").exists()


def test_retarget_bad_inputs(capsys, tmp_path):
    out = tmp_path / "out.bvh"
    code, _, err = run(capsys, "retarget", LAMP, "--to", CMU, "-o", out)
    line = one_error(err)
    assert code == 1 and line.startswith(f"{LAMP}: found no joint for the humanoid roles hips, ")
    assert "upper_arm_l" in line and "--rig-map" in line and "--to-rig-map" not in line
    code, _, err = run(capsys, "retarget", MIXAMO, "--to", LAMP, "-o", out)
    line = one_error(err)
    assert code == 1 and line.startswith(f"{LAMP}: found no joint") and "--to-rig-map" in line
    code, _, err = run(capsys, "retarget", MIXAMO, "--to", tmp_path / "none.bvh", "-o", out)
    assert code == 2 and one_error(err) == f"{tmp_path / 'none.bvh'}: no such file"
    bad = toml(tmp_path, 'hand_l = "mixamorig:NoSuchHand"\n')
    code, _, err = run(capsys, "retarget", CMU, "--to", MIXAMO, "--to-rig-map", bad, "-o", out)
    line = one_error(err)
    assert code == 2 and line.startswith("--to-rig-map: ") and "'mixamorig:NoSuchHand'" in line and str(MIXAMO) in line
    code, _, err = run(capsys, "retarget", MIXAMO, "--to", CMU, "--rig-map", toml(tmp_path, "wing_l = 'x'\n"), "-o", out)
    assert code == 1 and "'wing_l' is no humanoid role" in one_error(err)
    code, _, err = run(capsys, "retarget", MIXAMO, "--to", "-", "-o", out)
    assert code == 2 and "--to names a rig file" in one_error(err)
    code, _, err = run(capsys, "retarget", MIXAMO, "--to", CMU, "-o", "-")
    assert code == 2 and "--format" in one_error(err)
    assert not out.exists()
    # a batch onto a rig that is no humanoid stops before any input is read
    code, _, err = run(capsys, "retarget", MIXAMO, CMU, "--to", LAMP, "-o", tmp_path / "outdir/")
    assert code == 1 and "--to-rig-map" in one_error(err) and not (tmp_path / "outdir").exists()


def test_retarget_with_rig_maps(capsys, tmp_path):
    grip = renamed_mixamo(tmp_path)
    out = tmp_path / "out.bvh"
    code, _, err = run(capsys, "retarget", grip, "--to", CMU, "-o", out)
    line = one_error(err)
    assert code == 1 and "hand_l" in line and "--rig-map" in line and not out.exists()
    given = toml(tmp_path, f'hand_l = "{GRIP}"\n')
    code, stdout, err = run(capsys, "retarget", grip, "--to", CMU, "--rig-map", given, "-o", out, "--json")
    assert code == 0, err
    assert json.loads(stdout)["source_rig"]["hand_l"] == GRIP
    reference = tmp_path / "reference.bvh"
    assert run(capsys, "retarget", MIXAMO, "--to", CMU, "-o", reference)[0] == 0
    np.testing.assert_allclose(io.load(out).world_positions(), io.load(reference).world_positions(), atol=1e-6)
    # and the rig's own map: the renamed file as the target
    code, _, err = run(capsys, "retarget", CMU, "--to", grip, "--to-rig-map", given, "-o", tmp_path / "g.bvh")
    assert code == 0, err
    assert io.load(tmp_path / "g.bvh").skeleton.names[12] == GRIP


# --- keyfill info --rig -----------------------------------------------------------------


def test_info_rig_mixamo(capsys):
    code, out, err = run(capsys, "info", MIXAMO, "--rig")
    assert code == 0, err
    lines = out.splitlines()
    roles = lines[lines.index("humanoid roles:") + 1: lines.index("shipped human models:")]
    assert roles[0] == "  hips: mixamorig:Hips"
    assert "  spine: mixamorig:Spine, mixamorig:Spine1, mixamorig:Spine2" in roles
    assert "  clavicle_l: mixamorig:LeftShoulder" in roles and "  shin_r: mixamorig:RightLeg" in roles
    models = lines[lines.index("shipped human models:") + 1:]
    assert models == ["  transformer (bandai2-transformer, 30 fps): through retargeting",
                      "  gan (bandai2-gan, 30 fps): through retargeting",
                      "  match (bandai2-library, 30 fps): through retargeting"]
    code, out, _ = run(capsys, "info", MIXAMO, "--rig", "--json")
    d = json.loads(out)
    assert d["rig"]["hand_l"] == "mixamorig:LeftHand" and d["rig"]["neck"] == ["mixamorig:Neck"]
    assert d["models"]["transformer"] == {"model": "bandai2-transformer", "model_fps": 30.0,
                                          "fits": "through retargeting", "resampled": False}
    assert d["frames"] == 69  # the rest of the summary is there too


def test_info_rig_cmu_at_120_fps(capsys):
    code, out, err = run(capsys, "info", CMU, "--rig", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["rig"]["spine"] == ["LowerBack", "Spine", "Spine1"] and d["rig"]["neck"] == ["Neck", "Neck1"]
    assert "thigh_l" in d["rig"] and d["rig"]["thigh_l"] == "LeftUpLeg"
    assert d["models"]["gan"]["fits"] == "through retargeting" and d["models"]["gan"]["resampled"] is True
    code, out, _ = run(capsys, "info", CMU, "--rig")
    assert "  gan (bandai2-gan, 30 fps): through retargeting, resampled from 120 fps" in out.splitlines()


def test_info_rig_on_the_model_skeleton():
    bandai = shared_path("bvh_fixtures", "dataset-1_walk_normal_002.bvh")
    from keyfill.learn.registry import humanoid_fit

    roles, models = humanoid_fit(io.load(bandai), label=str(bandai))
    assert roles.to_json()["hips"] == "Hips"
    assert {m["fits"] for m in models.values()} == {"own skeleton"}


def test_info_rig_refuses_the_lamp(capsys, tmp_path):
    code, out, err = run(capsys, "info", LAMP, "--rig")
    line = one_error(err)
    assert code == 1 and out == ""
    assert line.startswith(f"{LAMP}: found no joint for the humanoid roles hips, ") and "--rig-map" in line
    # a rig map naming a joint the file lacks: the joint and the flag
    code, _, err = run(capsys, "info", MIXAMO, "--rig-map", toml(tmp_path, 'head = "Skull"\n'))
    line = one_error(err)
    assert code == 2 and line.startswith("--rig-map: ") and "'Skull'" in line


def test_info_rig_map_gives_a_role(capsys, tmp_path):
    grip = renamed_mixamo(tmp_path)
    code, _, err = run(capsys, "info", grip, "--rig")
    assert code == 1 and "hand_l" in one_error(err)
    code, out, err = run(capsys, "info", grip, "--rig-map", toml(tmp_path, f'hand_l = "{GRIP}"\n'), "--json")
    assert code == 0, err
    rig = json.loads(out)["rig"]
    assert rig["hand_l"] == GRIP and rig["forearm_l"] == "mixamorig:LeftForeArm"


@pytest.mark.parametrize("extra", [[], ["--rig"]])
def test_info_imports_no_torch(extra):
    code = ("import sys; from keyfill.cli.main import main; "
            f"assert main(['info', {str(MIXAMO)!r}, *{extra!r}]) == 0; "
            "assert 'torch' not in sys.modules, 'torch imported'")
    done = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


# --- keyfill complete --rig-map ---------------------------------------------------------


def test_complete_with_a_rig_map(capsys, tmp_path, one_torch_thread):
    grip = renamed_mixamo(tmp_path)
    out = tmp_path / "out.bvh"
    given = toml(tmp_path, f'hand_l = "{GRIP}"\n')
    code, stdout, err = run(capsys, "complete", grip, "--key-every", 10, "--method", "transformer",
                            "--rig-map", given, "-o", out, "--json")
    assert code == 0, err
    report = json.loads(stdout)
    assert report["rig"]["hand_l"] == GRIP and report["rig"]["forearm_l"] == "mixamorig:LeftForeArm"
    source, filled = io.load(grip), io.load(out)
    assert filled.skeleton.names == source.skeleton.names and filled.skeleton.channels == source.skeleton.channels
    assert filled.num_frames == source.num_frames and filled.fps == source.fps
    keys = report["keys"]
    np.testing.assert_allclose(filled.world_positions()[keys], source.world_positions()[keys], atol=1e-4)
    assert np.abs(filled.world_positions() - source.world_positions()).max() > 1e-3  # in-betweens were made


def test_complete_rig_map_errors(capsys, tmp_path):
    grip = renamed_mixamo(tmp_path)
    out = tmp_path / "out.bvh"
    code, _, err = run(capsys, "complete", grip, "--key-every", 10, "--method", "transformer", "-o", out)
    line = one_error(err)
    assert code == 1 and "hand_l" in line and "--rig-map" in line
    missing = toml(tmp_path, 'hand_l = "mixamorig:LeftPaw"\n')
    code, _, err = run(capsys, "complete", grip, "--key-every", 10, "--method", "gan", "--rig-map", missing, "-o", out)
    line = one_error(err)
    assert code == 2 and "'mixamorig:LeftPaw'" in line and line.startswith("--rig-map: ")
    code, _, err = run(capsys, "complete", MIXAMO, "--key-every", 10, "--method", "cubic", "--rig-map", missing,
                       "-o", out)
    line = one_error(err)
    assert code == 2 and line.startswith("--rig-map applies to methods") and "'cubic'" in line
    assert "transformer" in line and "gan" in line
    code, _, err = run(capsys, "complete", MIXAMO, "--key-every", 10, "--method", "gan", "--rig-map",
                       tmp_path / "none.toml", "-o", out)
    assert code == 2 and "none.toml" in one_error(err)
    code, _, err = run(capsys, "complete", MIXAMO, "--method", "gan", "--rig-map", toml(tmp_path, "hips = [\n"),
                       "-o", out)
    assert code == 1 and "not a TOML rig map" in one_error(err)
    assert not out.exists()


def test_complete_batch_carries_the_rig_map(capsys, tmp_path):
    grip = renamed_mixamo(tmp_path)
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "grip.bvh").write_bytes(grip.read_bytes())
    missing = toml(tmp_path, 'hand_l = "mixamorig:LeftPaw"\n')
    code, out, err = run(capsys, "complete", folder, "--key-every", 10, "--method", "transformer", "--rig-map", missing,
                         "-o", tmp_path / "out/", "--json")
    assert code == 1
    line = one_error(err)
    assert line.startswith(f"{folder / 'grip.bvh'}: ") and "'mixamorig:LeftPaw'" in line and "--rig-map" in line
    assert json.loads(out)["failed"] == 1
    code, _, err = run(capsys, "complete", folder, "--key-every", 10, "--method", "linear", "--rig-map", missing,
                       "-o", tmp_path / "out/")
    assert code == 2 and "--rig-map applies to methods" in one_error(err)


def test_library_names_the_parameter():
    from keyfill.errors import UsageError
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.registry import checked_options, get

    with pytest.raises(UsageError) as e:
        checked_options(get("cubic"), CompleteOptions(rig_map="map.toml"))
    assert e.value.params == ("rig_map",) and str(e.value).startswith("rig_map applies to methods")
    assert checked_options(get("gan"), CompleteOptions(rig_map="map.toml")).rig_map == "map.toml"
