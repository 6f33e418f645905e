"""The shipped human models (the distribution models/bandai): they work with no training, and carry their licence.

``keyfill complete --method gan`` without ``--model`` uses ``bandai2-gan``
(``bandai2-gan-partial`` for partial keys), ``--method transformer`` uses
``bandai2-transformer``, on the Bandai-Namco skeleton of ``examples/human``; on
another skeleton they say which skeleton the model serves, the first joint that
differs and how to train a model instead.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA

from keyfill import io
from keyfill.cli.main import main
from keyfill.learn.gan.model import DEFAULT_MODEL, PARTIAL_MODEL
from keyfill.learn.transformer import model as transformer

pytestmark = pytest.mark.usefixtures("one_torch_thread")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "human"
EXAMPLE = EXAMPLES / "keys.usda"
#: each method's example: keys 2.3 s apart for the gan, 0.5 s for the transformer (at most 63 frames)
LAMP_KEYS = Path(__file__).resolve().parents[1] / "examples" / "lamp" / "keys.usda"
EXAMPLE_OF = {"gan": EXAMPLE, "transformer": EXAMPLES / "keys_15.usda"}
SHIPPED = (DEFAULT_MODEL, PARTIAL_MODEL, transformer.DEFAULT_MODEL)


@pytest.mark.parametrize("folder", SHIPPED, ids=lambda p: p.name)
def test_shipped_folder_has_weights_licence_and_card_within_25_mb(folder):
    files = {p.name: p for p in folder.iterdir()}
    assert {"config.json", "weights.safetensors", "LICENSE", "MODEL_CARD.md"} <= set(files)
    assert sum(p.stat().st_size for p in files.values()) <= 25 * 1024 * 1024
    assert "Attribution-NonCommercial 4.0 International" in files["LICENSE"].read_text()
    card = files["MODEL_CARD.md"].read_text()
    method = "transformer" if folder == transformer.DEFAULT_MODEL else "gan"
    assert "CC BY-NC 4.0" in card and "Bandai Namco Research" in card and f"keyfill train {method}" in card


def test_the_registry_names_each_shipped_model_for_evaluate_and_export():
    from keyfill.learn.registry import METHODS

    assert METHODS["gan"].default_model() == DEFAULT_MODEL
    assert METHODS["transformer"].default_model() == transformer.DEFAULT_MODEL


@pytest.mark.parametrize("method,suffix", [("gan", ".bvh"), ("gan", ".usda"), ("transformer", ".bvh")])
def test_complete_human_keys_with_no_model_option(tmp_path, capsys, method, suffix):
    out, example = tmp_path / f"walk{suffix}", EXAMPLE_OF[method]
    assert main(["-q", "complete", str(example), "-o", str(out), "--method", method, "--seed", "3"]) == 0
    keys, filled = io.load(example), io.load(out)
    k = keys.keys.frames
    assert filled.num_frames == keys.num_frames
    same = np.abs((filled.rotations[k] * keys.rotations[k]).sum(-1))  # q and -q are one rotation
    np.testing.assert_allclose(same, 1.0, atol=1e-9)
    np.testing.assert_allclose(filled.positions[k], keys.positions[k], atol=1e-4)  # cm; USD keeps 32-bit floats
    between = np.setdiff1d(np.arange(keys.num_frames), k)
    assert np.abs(np.diff(filled.positions[between, 1], axis=0)).max() < 50.0  # cm per frame: no jumps


def test_partial_keys_use_the_shipped_partial_key_model(tmp_path, capsys):
    out = tmp_path / "path.bvh"
    assert main(["complete", str(EXAMPLE), "-o", str(out), "--method", "gan", "--key-joints", "Hips",
                 "--key-positions", "--json"]) == 0
    assert PARTIAL_MODEL.name in capsys.readouterr().out
    keys, filled = io.load(EXAMPLE), io.load(out)
    k = keys.keys.frames
    np.testing.assert_allclose(filled.positions[k, 1], keys.positions[k, 1], atol=1e-6)  # the keyed hips


def test_a_dna_file_does_not_replace_the_model_name_in_the_report(tmp_path, capsys):
    out = tmp_path / "walk.bvh"
    assert main(["complete", str(EXAMPLE), "-o", str(out), "--method", "gan", "--dna", f"{EXAMPLE}:0",
                 "--json"]) == 0
    assert f'"model": "{DEFAULT_MODEL.name}"' in capsys.readouterr().out


@pytest.mark.parametrize("method,hint", [("gan", "keyfill train gan CLIPS -o MODEL-path --stage path"),
                                         ("transformer", "keyfill train transformer CLIPS -o MODEL")])
def test_a_skeleton_that_is_no_humanoid_names_the_model_skeleton_and_the_training_command(tmp_path, capsys,
                                                                                          method, hint):
    out = tmp_path / "lamp.bvh"
    code = main(["complete", str(LAMP_KEYS), "-o", str(out), "--method", method])
    err = capsys.readouterr().err.strip()
    assert code == 1 and not out.exists() and len(err.splitlines()) == 1
    assert err.startswith("keyfill: error: the motion has another skeleton than the model (22 joints, top joint "
                          "'joint_Root'): the model's vs the motion's: 22 joints vs 4; the first that differs is "
                          "joint 0, 'joint_Root' vs ")
    assert hint in err
    assert "; nor can it be retargeted: the skeleton: found no joint for the humanoid roles" in err
    assert "--rig-map" in err


@pytest.mark.parametrize("method", ["gan", "transformer"])
@pytest.mark.parametrize("fixture", ["cmu_02_03_cgspeed_first4frames.bvh", "bvhtoolbox_test_freebvh_mixamo.bvh"])
def test_another_humanoid_is_retargeted_and_keeps_its_own_layout(tmp_path, capsys, method, fixture):
    src = io.load(DATA / fixture)
    out = tmp_path / "out.bvh"
    keys = "0,3" if src.num_frames == 4 else "0,10,20,30,40,50,60,68"
    assert main(["complete", str(DATA / fixture), "-o", str(out), "--keys", keys, "--method", method,
                 "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["rig"]["hips"] == src.skeleton.names[0] and info["model_fps"] == 30.0
    filled = io.load(out)
    assert filled.skeleton.names == src.skeleton.names and filled.skeleton.channels == src.skeleton.channels
    assert filled.fps == src.fps and filled.num_frames == src.num_frames
    k = [int(x) for x in keys.split(",")]
    np.testing.assert_allclose(filled.positions[k], src.positions[k], atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(filled.rotations[k] * src.rotations[k], -1)), 1.0, atol=1e-9)


def test_a_dna_clip_of_another_rig_is_retargeted_onto_the_model(tmp_path):
    mixamo = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
    outs = {}
    for name, dna in (("own", f"{EXAMPLE}:0,100,200"), ("mixamo", f"{mixamo}:10,30,50")):
        outs[name] = tmp_path / f"{name}.bvh"
        assert main(["complete", str(EXAMPLE), "-o", str(outs[name]), "--method", "gan", "--dna", dna]) == 0
    own, other = io.load(outs["own"]), io.load(outs["mixamo"])
    assert own.skeleton.names == other.skeleton.names
    # the Mixamo poses steer it elsewhere, if only a little: the second recipe's Motion DNA moves this example's
    # rotations by at most 8e-4 (0.65 cm) between these two DNAs (docs/gan.md: DNA steers weakly)
    assert not np.allclose(own.rotations, other.rotations, atol=1e-4)


def test_partial_keys_work_across_rigs(tmp_path, capsys):
    src = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
    out = tmp_path / "path.bvh"
    assert main(["complete", str(src), "-o", str(out), "--keys", "0,30,68", "--key-joints", "mixamorig:Hips",
                 "--key-positions", "--method", "gan", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["model"] == PARTIAL_MODEL.name and info["rig"]["hips"] == "mixamorig:Hips"
    a, b = io.load(src), io.load(out)
    np.testing.assert_allclose(b.positions[[0, 30, 68], 0], a.positions[[0, 30, 68], 0], atol=1e-9)
    assert b.skeleton.names == a.skeleton.names
