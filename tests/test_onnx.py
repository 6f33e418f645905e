"""ONNX export and the torch-free runtime: parity with torch, metadata binding, refusals, no torch import."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")

from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import io
from keyfill import rotations as R
from keyfill.cli.main import main
from keyfill.learn import onnx as kx
from keyfill.motion import Keys

ROOT = Path(__file__).resolve().parents[1]
LAMP_KEYS = ROOT / "examples" / "lamp" / "keys.usda"
TINY = {"layers": 2, "d_model": 32, "heads": 4, "ffn": 64, "dropout": 0.0, "max_frames": 65}


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def relative_error(a, b) -> float:
    """Largest difference relative to the data's scale (its largest magnitude)."""
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(np.asarray(b)).max(), 1e-12))


def random_transformer(folder: Path, seed: int, **settings):
    """A tiny transformer model folder with random weights (every layer, the zero-initialised output too)."""
    import torch

    from keyfill.learn.transformer import config as TC
    from keyfill.learn.transformer import model as T

    skeleton = walker_skeleton(static_root=False)
    motion = walker_motion(skeleton, 60, np.random.default_rng(seed))
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        model = T.new_model(skeleton, TC.ModelConfig(**TINY, **settings), np.zeros(skeleton.num_joints * 3),
                            np.full(skeleton.num_joints * 3, 30.0), folded=False)
        with torch.no_grad():
            for p in model.network.parameters():
                p.add_(0.05 * torch.randn(p.shape))
    model.save(folder)
    return motion


@pytest.fixture(scope="module")
def transformer(tmp_path_factory, one_torch_thread):
    """``(model folder with its exported graph, a motion it serves)``."""
    folder = tmp_path_factory.mktemp("tf") / "model"
    motion = random_transformer(folder, 0)
    assert main(["export", str(folder)]) == 0
    return folder, motion


@pytest.fixture(scope="module")
def lamp_graph(tmp_path_factory, one_torch_thread):
    out = tmp_path_factory.mktemp("arnn") / "lamp-arnn.onnx"
    assert main(["export", "arnn", "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def transformer_with_key_distances(tmp_path_factory, one_torch_thread):
    folder = tmp_path_factory.mktemp("tf-kd") / "model"
    random_transformer(folder, 2, key_distances=True)
    assert main(["export", str(folder)]) == 0
    return folder, None


@pytest.fixture(scope="module")
def transformer_reading_zeros(tmp_path_factory, one_torch_thread):
    """issue 46's input: zero-filled unknown frames, a mask and velocities, computed inside the graph."""
    folder = tmp_path_factory.mktemp("tf-zero") / "model"
    random_transformer(folder, 3, unknown_input="zero", velocity_input=True)
    assert main(["export", str(folder)]) == 0
    return folder, None


@pytest.mark.parametrize("which", ["transformer", "transformer_with_key_distances", "transformer_reading_zeros"])
def test_transformer_graph_equals_torch_on_random_inputs(which, request):
    import torch

    from keyfill.learn.transformer import model as T

    folder, _ = request.getfixturevalue(which)
    model = T.load(folder)
    graph = kx.Graph(folder / kx.GRAPH)
    rng = np.random.default_rng(1)
    F = model.features.size
    for B, frames in ((1, 30), (3, 17), (2, 65), (4, 2)):
        x = rng.normal(size=(B, frames, F)).astype(np.float32)
        kinds = rng.integers(0, 3, size=(B, frames))
        with torch.inference_mode():
            ref = model.network(torch.from_numpy(x), torch.from_numpy(kinds)).numpy()
        out = graph.run({"features": x, "kinds": kinds})[0]
        assert out.shape == ref.shape
        assert relative_error(out, ref) < 1e-4, (B, frames)


def test_transformer_completion_with_onnx_equals_torch(transformer, tmp_path, capsys):
    folder, motion = transformer
    src = tmp_path / "walk.bvh"
    io.save(motion.replace(keys=Keys([0, 10, 25, 40, 59])), src)
    results = {}
    for runtime in ("torch", "onnx"):
        code, out, err = run(capsys, "complete", src, "-o", tmp_path / f"{runtime}.bvh", "--method", "transformer",
                             "--model", folder, "--keys", "0,10,25,40,59", "--runtime", runtime, "--json")
        assert code == 0, err
        results[runtime] = io.load(tmp_path / f"{runtime}.bvh")
        assert json.loads(out).get("runtime", "torch") == runtime
    a, b = results["onnx"], results["torch"]
    assert relative_error(a.positions, b.positions) < 1e-4
    # the same rotations (their BVH Euler curves may differ by whole turns, which flips a quaternion's sign)
    assert R.quat_angle(a.rotations, b.rotations).max() < 1e-4
    # auto picks the graph in the model folder when onnxruntime is there
    code, out, err = run(capsys, "complete", src, "-o", tmp_path / "auto.bvh", "--method", "transformer",
                         "--model", folder, "--keys", "0,10,25,40,59", "--json")
    assert code == 0 and json.loads(out)["runtime"] == "onnx"
    assert (tmp_path / "auto.bvh").read_bytes() == (tmp_path / "onnx.bvh").read_bytes()


def test_the_graph_metadata_holds_the_contract(transformer):
    folder, _ = transformer
    graph = kx.Graph(folder / kx.GRAPH)
    assert graph.kind == "transformer" and graph.weights_sha256 == kx.weights_digest(folder)
    assert graph.config == json.loads((folder / "config.json").read_text())
    assert list(graph.contract["inputs"]) == ["features", "kinds"] and graph.contract["max_frames"] == 65
    assert [i.name for i in graph.session.get_inputs()] == ["features", "kinds"]


def test_lamp_graph_equals_torch_on_the_shipped_model_and_random_sequences(lamp_graph):
    from keyfill.characters.lamp import to_variables
    from keyfill.learn.arnn import model as arnn
    from keyfill.learn.arnn.onnx import OnnxLampModel
    from keyfill.learn.lamp_data import LampSequence

    torch_model = arnn.load(arnn.DEFAULT_MODEL)
    onnx_model = OnnxLampModel(kx.Graph(lamp_graph))
    motion = io.load(LAMP_KEYS)
    k = motion.keys.frames
    values = np.zeros((motion.num_frames, 6))
    values[k] = to_variables(motion.frames(k))
    sequences = [LampSequence(values, k)]
    rng = np.random.default_rng(2)
    for n in (2, 9, 30, 87, 140):
        keys = np.unique(np.r_[0, rng.integers(1, n - 1, size=min(4, n - 2)) if n > 2 else [], n - 1]).astype(int)
        sequences.append(LampSequence(rng.normal(scale=0.5, size=(n, 6)), keys))
    scale = torch_model.normalizer.std
    for one in ([sequences[0]], sequences):
        for a, b in zip(onnx_model.predict(one), torch_model.predict(one)):
            assert (np.abs(a - b) / scale).max() < 1e-4


@pytest.mark.parametrize("arch", ["no-memory", "segregated"])
def test_every_lamp_architecture_exports(arch, tmp_path, one_torch_thread):
    import torch

    from keyfill.learn.arnn import model as arnn
    from keyfill.learn.arnn import network as arnn_network
    from keyfill.learn.arnn import onnx as arnn_onnx
    from keyfill.learn.arnn.onnx import OnnxLampModel
    from keyfill.learn.lamp_data import LampSequence, Normalizer
    from keyfill.learn.modelfile import save_model

    net = arnn_network.build(arch, torch.Generator().manual_seed(3))
    normalizer = Normalizer(np.zeros(6), np.ones(6))
    save_model(tmp_path / "m", "arnn", net.state_dict(), arnn.model_config(net, normalizer, {}, {}))
    model = arnn.load(tmp_path / "m")
    arnn_onnx.export_onnx(model, tmp_path / "m", tmp_path / "m.onnx")
    rng = np.random.default_rng(4)
    seqs = [LampSequence(rng.normal(size=(n, 6)), [0, n // 2, n - 1]) for n in (5, 33)]
    for a, b in zip(OnnxLampModel(kx.Graph(tmp_path / "m.onnx")).predict(seqs), model.predict(seqs)):
        assert np.abs(a - b).max() < 1e-4


def test_onnx_runtime_imports_no_torch(lamp_graph, transformer, tmp_path):
    folder, motion = transformer
    io.save(motion.replace(keys=Keys([0, 20, 40, 59])), tmp_path / "walk.bvh")
    code = (
        "import sys\n"
        "from keyfill.cli.main import main\n"
        f"assert main(['complete', {str(LAMP_KEYS)!r}, '-o', {str(tmp_path / 'lamp.usda')!r}, '--method', 'arnn',"
        f" '--model', {str(lamp_graph)!r}, '--runtime', 'onnx']) == 0\n"
        f"assert main(['complete', {str(tmp_path / 'walk.bvh')!r}, '-o', {str(tmp_path / 'w.bvh')!r},"
        f" '--method', 'transformer', '--model', {str(folder)!r}, '--keys', '0,20,40,59']) == 0\n"
        "assert 'torch' not in sys.modules, sorted(m for m in sys.modules if m.startswith('torch'))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, check=False)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "lamp.usda").is_file() and (tmp_path / "w.bvh").is_file()


def test_a_model_without_a_graph_says_how_to_export(tmp_path, capsys):
    from keyfill.learn.arnn.model import DEFAULT_MODEL

    folder = tmp_path / "lamp"  # the shipped lamp model without the graph it ships with
    shutil.copytree(DEFAULT_MODEL, folder, ignore=shutil.ignore_patterns(kx.GRAPH))
    code, _out, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "x.usda", "--method", "arnn",
                          "--model", folder, "--runtime", "onnx")
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert "has no exported graph" in err and f"keyfill export {folder}" in err
    assert not (tmp_path / "x.usda").exists()


def test_the_shipped_transformer_and_lamp_models_run_their_graphs_without_torch(tmp_path):
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    for example, method in ((LAMP_KEYS, "arnn"), (root / "examples" / "human" / "keys_15.usda", "transformer")):
        out = tmp_path / f"{method}.usda"
        code = ("import sys; sys.modules['torch'] = None  # the base install: no torch\n"
                "from keyfill.cli.main import main\n"
                f"sys.exit(main(['complete', {str(example)!r}, '-o', {str(out)!r}, '--method', {method!r}]))")
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
        assert r.returncode == 0, r.stderr
        assert io.load(out).num_frames == io.load(example).num_frames


def test_a_graph_of_other_weights_is_refused(transformer, tmp_path, capsys):
    folder, motion = transformer
    other = tmp_path / "other"
    random_transformer(other, 1)
    shutil.copy(folder / kx.GRAPH, other / kx.GRAPH)
    io.save(motion.replace(keys=Keys([0, 20, 40, 59])), tmp_path / "walk.bvh")
    keys = ("--keys", "0,20,40,59")
    for runtime in ("onnx", "auto"):
        code, _out, err = run(capsys, "complete", tmp_path / "walk.bvh", "-o", tmp_path / "x.bvh", "--method",
                             "transformer", "--model", other, "--runtime", runtime, *keys)
        assert code == 1 and "exported from other weights" in err and f"keyfill export {other}" in err
    # a batch is refused before any work
    code, _out, err = run(capsys, "complete", tmp_path / "walk.bvh", "-o", f"{tmp_path / 'out'}/", "--method",
                         "transformer", "--model", other, *keys)  # a str: a Path drops the trailing slash
    assert code == 1 and "exported from other weights" in err and not (tmp_path / "out").exists(), err
    assert not (tmp_path / "x.bvh").exists()
    # torch still works
    code, _out, err = run(capsys, "complete", tmp_path / "walk.bvh", "-o", tmp_path / "x.bvh", "--method",
                         "transformer", "--model", other, "--runtime", "torch", *keys)
    assert code == 0, err


def test_a_graph_of_another_method_is_refused(lamp_graph, tmp_path, capsys):
    code, _out, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "x.usda", "--method", "transformer",
                         "--model", lamp_graph)
    assert code == 2 and "a graph of a 'arnn' model, not 'transformer'" in err
    (tmp_path / "fake.onnx").write_bytes(b"not a graph")
    code, _out, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "x.usda", "--method", "arnn",
                         "--model", tmp_path / "fake.onnx")
    assert code == 1 and "not a readable ONNX graph" in err


def test_batch_completion_through_the_graph(lamp_graph, tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    for i in range(3):
        shutil.copy(LAMP_KEYS, src / f"k{i}.usda")
    code, out, err = run(capsys, "complete", src, "-o", tmp_path / "out", "--method", "arnn", "--model", lamp_graph,
                         "--json")
    assert code == 0, err
    files = json.loads(out)["files"]
    assert [f["runtime"] for f in files] == ["onnx"] * 3
    code, _, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "torch.usda", "--method", "arnn")
    a, b = io.load(tmp_path / "out" / "k0.usda"), io.load(tmp_path / "torch.usda")
    assert np.abs(a.positions - b.positions).max() < 1e-5


def test_a_graph_beside_a_changed_config_is_refused(tmp_path, capsys):
    import json

    from keyfill.learn.arnn.model import DEFAULT_MODEL

    folder = tmp_path / "lamp"
    shutil.copytree(DEFAULT_MODEL, folder)
    config = json.loads((folder / "config.json").read_text())
    config["training"] = {**config.get("training", {}), "note": "edited"}
    (folder / "config.json").write_text(json.dumps(config))
    code, _out, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "x.usda", "--method", "arnn",
                          "--model", folder)
    assert code == 1 and "exported with another config.json" in err and f"keyfill export {folder}" in err
    assert not (tmp_path / "x.usda").exists()
