"""The gan's ONNX graph: parity with torch, the bank in the metadata, no torch at start-up, refusals."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")
torch = pytest.importorskip("torch")

from gan_helpers import fit, synthetic_corpus, tiny_config, world
from synthetic_corpus import walker_motion, walker_skeleton
from test_gan_recipe2 import RECIPE2

from keyfill import io
from keyfill.cli.main import main
from keyfill.learn import onnx as kx
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.registry import complete
from keyfill.motion import Keys

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """``(second-recipe model with Motion DNA and partial keys, with its graph; a model with noise)``."""
    from keyfill.learn.gan.task import GanTask

    root = tmp_path_factory.mktemp("gan_onnx")
    corpus = synthetic_corpus(root / "clips", clips_per_style=2)
    cfg = tiny_config(**{**RECIPE2, "max_frames": 256, "steps_per_epoch": 2, "style_dim": 4, "dna_width": 8,
                         "partial_keys": True})
    path_dir = fit(GanTask(corpus, cfg, "path", epochs=1), root / "path").model
    full = fit(GanTask(corpus, cfg, "generator", path_model=path_dir, epochs=1), root / "full").model
    assert main(["export", str(full)]) == 0
    noisy_cfg = tiny_config(max_frames=256, steps_per_epoch=1)
    noisy_path = fit(GanTask(corpus, noisy_cfg, "path", epochs=1), root / "noisy_path").model
    noisy = fit(GanTask(corpus, noisy_cfg, "generator", path_model=noisy_path, epochs=1), root / "noisy").model
    return full, noisy


@pytest.fixture(scope="module")
def motion():
    return walker_motion(walker_skeleton(), 240, np.random.default_rng(42))


@pytest.mark.parametrize("keys", [Keys(np.array([0, 50, 130, 200])), Keys(np.array([5, 20, 44])),
                                  Keys(np.array([0, 60, 120]), mask=np.array([[0, 1, 1, 1, 0, 0, 0, 0]] * 3, bool))],
                         ids=["whole", "under-64-frames", "partial"])
def test_graph_completion_equals_torch_within_1e_4_of_the_height(models, motion, keys, tmp_path):
    dna_file = tmp_path / "dna.bvh"
    io.save(walker_motion(walker_skeleton(), 90, np.random.default_rng(7)), dna_file)
    for dna in (None, f"{dna_file}:3,40,80"):
        out = {rt: complete(motion, keys, "gan", CompleteOptions(model=str(models[0]), seed=5, runtime=rt, dna=dna))
               for rt in ("torch", "onnx")}
        assert out["onnx"].info["runtime"] == "onnx" and "runtime" not in out["torch"].info
        a, b = out["torch"].motion, out["onnx"].motion
        height = np.ptp(world(a)[..., 1], axis=-1).max()
        assert np.abs(world(a) - world(b)).max() <= 1e-4 * height
        assert np.abs(a.rotations - b.rotations).max() <= 1e-4  # quaternion components
        assert out["onnx"].info["dna_poses"] == out["torch"].info["dna_poses"]


def test_batched_windows_through_the_graph_equal_torch(models, motion):
    from keyfill.learn.gan.model import load_model
    from keyfill.learn.gan.onnx import model_from_graph

    torch_model = load_model(models[0])
    graph_model = model_from_graph(kx.open_graph(models[0] / kx.GRAPH))
    assert np.array_equal(graph_model.bank.poses, torch_model.bank.poses)
    assert np.array_equal(graph_model.bank.clips, torch_model.bank.clips)
    from keyfill.learn.corpus import fold_root

    q, p = fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    quats, root = np.stack([q[0:150], q[60:210]]), np.stack([p[0:150, 0], p[60:210, 0]])
    keys = np.array([0, 70, 149])
    skeleton = torch_model.skeleton
    qa, ra = torch_model.benchmark_method(2)(skeleton, quats, root, keys)
    qb, rb = graph_model.benchmark_method(2)(skeleton, quats, root, keys)
    assert np.abs(qa - qb).max() <= 1e-4
    assert np.abs(ra - rb).max() <= 1e-4 * 130  # the walker is about 130 units tall


def test_the_graph_metadata_holds_the_contract_and_the_bank(models):
    graph = kx.open_graph(models[0] / kx.GRAPH)
    assert graph.kind == "gan"
    assert set(graph.contract["inputs"]) == {"dense", "dna", "dna_valid"}
    assert set(graph.contract["outputs"]) == {"quats", "root"}
    assert graph.contract["frame_multiple"] == 64
    assert json.loads(graph.metadata["keyfill.dna_bank"])["shape"][1:] == [7, 3]
    from keyfill.learn.gan.model import FRAME_MULTIPLE
    from keyfill.learn.gan.network import GENERATOR_MULTIPLE

    assert FRAME_MULTIPLE == GENERATOR_MULTIPLE


def test_gan_completion_through_the_graph_imports_no_torch(models, motion, tmp_path):
    src = tmp_path / "walk.bvh"
    io.save(motion, src)
    code = ("import sys\n"
            "from keyfill.cli.main import main\n"
            f"assert main(['complete', {str(src)!r}, '--method', 'gan', '--model', {str(models[0])!r}, "
            f"'--key-every', '40', '-o', {str(tmp_path / 'out.bvh')!r}]) == 0\n"
            f"assert main(['complete', {str(src)!r}, '--model', {str(models[0] / kx.GRAPH)!r}, '--keys', '0,60,120', "
            f"'--key-joints', 'Hips,Spine,Head', '-o', {str(tmp_path / 'partial.bvh')!r}]) == 0\n"
            "assert 'torch' not in sys.modules, sorted(m for m in sys.modules if m.startswith('torch'))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]


def test_a_model_with_noise_is_not_exported(models, capsys):
    code = main(["export", str(models[1])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("keyfill: error:") and "noise_dim 4" in err[0]
    assert not (models[1] / kx.GRAPH).exists()


def test_without_a_graph_auto_runs_torch_and_onnx_says_how_to_export(models, motion, capsys):
    keys = Keys(np.array([0, 60, 120]))
    done = complete(motion, keys, "gan", CompleteOptions(model=str(models[1])))
    assert "runtime" not in done.info
    src = models[1].parent / "walk.bvh"
    io.save(motion, src)
    code = main(["complete", str(src), "--method", "gan", "--model", str(models[1]), "--keys", "0,60,120",
                 "--runtime", "onnx", "-o", str(models[1].parent / "x.bvh")])
    err = capsys.readouterr().err
    assert code != 0 and "keyfill export" in err


def test_a_graph_beside_a_changed_config_is_refused(models, motion, tmp_path, capsys):
    folder = tmp_path / "changed"
    shutil.copytree(models[0], folder)
    config = json.loads((folder / "config.json").read_text())
    config["gan"]["output_smoothing"] = 4  # another post-processing than the graph's
    (folder / "config.json").write_text(json.dumps(config))
    src = tmp_path / "walk.bvh"
    io.save(motion, src)
    code = main(["complete", str(src), "--method", "gan", "--model", str(folder), "--keys", "0,60,120",
                 "-o", str(tmp_path / "out.bvh")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "another config.json" in err[0]


def test_without_model_partial_keys_use_the_partial_models_graph_or_torch(models, motion, tmp_path, monkeypatch):
    from keyfill.learn.gan import model as gan_model

    whole_dir, partial_dir = tmp_path / "whole", tmp_path / "partial"
    shutil.copytree(models[0], whole_dir)
    shutil.copytree(models[0], partial_dir, ignore=shutil.ignore_patterns(kx.GRAPH))
    monkeypatch.setattr(gan_model, "DEFAULT_MODEL", whole_dir)
    monkeypatch.setattr(gan_model, "PARTIAL_MODEL", partial_dir)
    whole = Keys(np.array([0, 60, 120]))
    partial = Keys(np.array([0, 60, 120]), mask=np.array([[0, 1, 1, 1, 0, 0, 0, 0]] * 3, bool))
    done = complete(motion, whole, "gan", CompleteOptions(seed=1))
    assert done.info["runtime"] == "onnx" and done.info["model"] == "whole"
    done = complete(motion, partial, "gan", CompleteOptions(seed=1))
    assert "runtime" not in done.info and done.info["model"] == "partial"  # no graph there: torch
    shutil.copy(models[0] / kx.GRAPH, partial_dir / kx.GRAPH)
    done = complete(motion, partial, "gan", CompleteOptions(seed=1))
    assert done.info["runtime"] == "onnx" and done.info["model"] == "partial"
