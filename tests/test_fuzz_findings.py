"""Issue 48: fuzz findings, each a small input built here that once cost gigabytes, minutes or an internal error.

Every case ends in one ``keyfill: error:`` line naming the file, the documented exit code (1 bad data, 2 usage),
no traceback, no warning and nothing written.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import struct
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, one_error_line, run

from keyfill import io

CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
HUMAN_KEYS = Path(__file__).parent.parent / "examples" / "human" / "keys_15.usda"
LAMP_KEYS = Path(__file__).parent.parent / "examples" / "lamp" / "keys.usda"


def _clean_run(capsys, *args):
    """``run`` with warnings as errors (pytest would swallow one a user sees printed above the line)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return run(capsys, *args)


def _data_uri(data: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


# --- 1. glTF amplification: shared sparse accessors ------------------------------------------------------


def shared_sparse(path: Path, joints: int = 420, count: int = 2_048_000 // 12) -> Path:
    """A ~55 kB .gltf: one sparse times, rotation and translation accessor of ~170k elements each (a few bytes
    of data: as many as one accessor may declare, limits.check_size), shared by the 840 channels of ``joints``
    joints: 2.2 billion numbers to read, 12 s before."""
    data = np.array([0, 1], "<f4").tobytes() + struct.pack("<I", 0) + np.array([0, 0, 0, 1, 0, 0, 0], "<f4").tobytes()
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": 8}, {"buffer": 0, "byteOffset": 8, "byteLength": 4},
             {"buffer": 0, "byteOffset": 12, "byteLength": 16}, {"buffer": 0, "byteOffset": 28, "byteLength": 12}]

    def sparse(kind, values_view):
        return {"componentType": 5126, "type": kind, "count": count,
                "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5125},
                           "values": {"bufferView": values_view}}}

    channels = [{"sampler": s, "target": {"node": j, "path": path}}
                for j in range(joints) for s, path in ((0, "rotation"), (1, "translation"))]
    doc = {"asset": {"version": "2.0"}, "nodes": [{"name": f"j{j}"} for j in range(joints)],
           "skins": [{"joints": list(range(joints))}],
           "animations": [{"samplers": [{"input": 0, "output": 1, "interpolation": "STEP"},
                                        {"input": 0, "output": 2, "interpolation": "STEP"}],
                           "channels": channels}],
           "accessors": [sparse("SCALAR", 0), sparse("VEC4", 2), sparse("VEC3", 3)], "bufferViews": views,
           "buffers": [{"byteLength": len(data), "uri": _data_uri(data)}]}
    path.write_text(json.dumps(doc, separators=(",", ":")))
    return path


def test_accessors_shared_by_many_channels_are_counted_each_time(capsys, tmp_path):
    bad = shared_sparse(tmp_path / "shared.gltf")
    assert bad.stat().st_size < 60_000
    start = time.perf_counter()
    code, out, err = _clean_run(capsys, "convert", bad, tmp_path / "out.bvh")
    line = one_error_line(err)
    assert code == 1 and str(bad) in line and "numbers from its accessors" in line, line
    assert "KEYFILL_FREE_ACCESSOR_READS" in line
    assert time.perf_counter() - start < 5  # was 12 s (and 4 GB allocated in turn)
    assert not (tmp_path / "out.bvh").exists() and out == ""


def test_the_accessor_budget_can_be_raised_and_real_files_stay_far_below_it(monkeypatch, tmp_path):
    from keyfill.io import gltf, gltf_buffers

    docs = []

    def spy(*args):
        docs.append(gltf_buffers.load_document(*args))
        return docs[-1]

    monkeypatch.setattr(gltf, "load_document", spy)
    io.save(io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"), tmp_path / "m.glb")
    io.load(tmp_path / "m.glb")
    assert docs[-1].reads < docs[-1].size / 2  # keyfill's own files: each number read at most twice, 4 bytes each
    monkeypatch.setenv("KEYFILL_FREE_ACCESSOR_READS", str(10**7))
    small = shared_sparse(tmp_path / "small.gltf", joints=20, count=100_000)  # 28 million numbers
    with pytest.raises(io.FormatError, match="numbers from its accessors"):
        io.load(small)
    monkeypatch.setenv("KEYFILL_FREE_ACCESSOR_READS", str(10**9))
    with pytest.raises(io.FormatError, match="rotation is zero"):  # past the budget: the sparse zeros themselves
        io.load(small)


# --- 2. node chains: linear ------------------------------------------------------------------------------


def node_chain(path: Path, n: int = 1450, moving: bool = False) -> Path:
    """A .gltf of ``n`` nodes that are no joints in a chain, each with a joint under it: every joint walked
    the chain above it (quadratic: past 60 s for 1,450)."""
    nodes = [{"children": [n + i] + ([i + 1] if i + 1 < n else [])} for i in range(n)]
    nodes += [{"name": f"j{i}"} for i in range(n)]
    joints = list(range(n, 2 * n))
    if moving:  # joint 0 above the chain, which moves the joints under it
        nodes.append({"name": "top", "children": [0]})
        nodes[n // 2]["translation"] = [0, 1, 0]
        joints.append(2 * n)
    doc = {"asset": {"version": "2.0"}, "nodes": nodes, "skins": [{"joints": joints}]}
    path.write_text(json.dumps(doc, separators=(",", ":")))
    return path


def test_a_long_chain_of_nodes_above_the_joints_is_read_in_linear_time(capsys, tmp_path):
    src = node_chain(tmp_path / "chain.gltf")
    start = time.perf_counter()
    motion = io.load(src)
    assert time.perf_counter() - start < 10  # 1.4 s for the whole convert (was past 60 s)
    assert motion.num_joints == 1450 and np.all(motion.skeleton.parents == -1)
    bad = node_chain(tmp_path / "moving.gltf", n=300, moving=True)
    code, _, err = _clean_run(capsys, "convert", bad, tmp_path / "out.bvh")
    line = one_error_line(err)
    assert code == 1 and str(bad) in line and "is not a joint of skin 0 and moves it" in line, line
    assert not (tmp_path / "out.bvh").exists()


def test_the_nodes_above_a_root_are_folded_into_it(tmp_path):
    """The memoised walk gives what the walk per joint gave: the product of the nodes above each root."""
    nodes = [{"translation": [1, 0, 0], "children": [1, 3]}, {"rotation": [0, 0, 0.7071067811865476,
                                                                          0.7071067811865476], "children": [2]},
             {"name": "a", "translation": [0, 1, 0]}, {"name": "b", "translation": [0, 0, 1]}]
    doc = {"asset": {"version": "2.0"}, "nodes": nodes, "skins": [{"joints": [2, 3]}]}
    (tmp_path / "up.gltf").write_text(json.dumps(doc))
    motion = io.load(tmp_path / "up.gltf")
    world = motion.frames(slice(0, 1)).world_positions()[0] * motion.skeleton.meters_per_unit
    assert np.allclose(world, [[0, 0, 0], [1, 0, 1]], atol=1e-9), world  # a: (1,0,0) + (0,1,0) turned 90 deg about z


# --- 3. numbers and URIs in glTF JSON --------------------------------------------------------------------


def _base(tmp_path) -> tuple[dict, Path]:
    src = tmp_path / "base.gltf"
    io.save(io.load(CMU), src)
    return json.loads(src.read_text()), src


def _keys(doc, keys):
    doc["animations"][0]["extras"]["keyfill"]["keys"] = keys
    return json.dumps(doc)


JSON_CASES = {
    "integer of 5,000 digits": (lambda d: json.dumps(d).replace('"asset"', '"n": ' + "9" * 5000 + ', "asset"', 1),
                                "the integer 999999999999... does not fit in 64 bits"),
    "keys beyond int64": (lambda d: _keys(d, [0, 2**64]), "does not fit in 64 bits"),
    "keys below int64": (lambda d: _keys(d, [0, -(2**63) - 1]), "does not fit in 64 bits"),
    "keys within int64 far beyond the motion": (lambda d: _keys(d, [0, 2**62]), "4611686018427387904"),
    "fps of 401 digits": (lambda d: json.dumps(d).replace('"fps": 120.0', '"fps": ' + "1" * 401),
                          "does not fit in 64 bits"),
    "fps 1e400": (lambda d: json.dumps(d).replace('"fps": 120.0', '"fps": 1e400'), "1e400 is not a finite number"),
    "fps a huge integer": (lambda d: json.dumps(d).replace('"fps": 120.0', '"fps": 9223372036854775807'),
                           "frame rate"),
    "1e400 in other extras": (lambda d: json.dumps(d).replace('"asset": {', '"extras": {"x": 1e400}, "asset": {', 1),
                              "1e400 is not a finite number"),
    "buffer URI with %00": (lambda d: json.dumps({**d, "buffers": [{**d["buffers"][0], "uri": "base%00.bin"}]}),
                            "holds a NUL byte"),
    "buffer URI of 300 characters": (lambda d: json.dumps({**d, "buffers": [{**d["buffers"][0],
                                                                              "uri": "a" * 300 + ".bin"}]}),
                                     "names no file that can be read"),
}


@pytest.mark.parametrize("case", sorted(JSON_CASES))
@pytest.mark.parametrize("suffix", [".bvh", ".gltf"])  # .gltf: the glTF writer keeps the source's JSON
def test_numbers_and_uris_in_gltf_json_are_one_clean_error(capsys, tmp_path, case, suffix):
    doc, _ = _base(tmp_path)
    change, fragment = JSON_CASES[case]
    bad = tmp_path / "bad.gltf"
    bad.write_text(change(doc))
    out = tmp_path / f"out{suffix}"
    code, stdout, err = _clean_run(capsys, "convert", bad, out)
    line = one_error_line(err)
    assert code == 1 and str(bad) in line and fragment in line, line
    assert not out.exists() and not out.with_suffix(".bin").exists() and stdout == ""


# --- 4. --rig-map files ----------------------------------------------------------------------------------


@pytest.mark.parametrize("content,fragment", [
    ("hips = " + "9" * 5000 + "\n", "not a usable rig map"),
    ("spine = " + "[" * 3000 + "]" * 3000 + "\n", "nested too deeply"),
    ("hips = \"a\"\n" + "#" * (2**20) + "\n", "longer than 1,048,576 bytes"),
    (None, "must be a regular file"),  # /dev/zero: read to the end, it fills the memory
    ("fifo", "must be a regular file"),  # a FIFO without a writer: opened without waiting
])
@pytest.mark.parametrize("command", ["info", "retarget"])
def test_rig_maps_are_small_regular_toml_files(capsys, tmp_path, content, fragment, command):
    if content is None:
        rig_map = Path("/dev/zero")
    elif content == "fifo":
        rig_map = tmp_path / "map.toml"
        os.mkfifo(rig_map)
    else:
        rig_map = tmp_path / "map.toml"
        rig_map.write_text(content)
    out = tmp_path / "out.bvh"
    args = (["info", CMU, "--rig-map", rig_map] if command == "info"
            else ["retarget", CMU, "--to", CMU, "-o", out, "--rig-map", rig_map])
    start = time.perf_counter()
    code, stdout, err = _clean_run(capsys, *args)
    line = one_error_line(err)
    assert code == 1 and str(rig_map) in line and fragment in line, line
    assert stdout == "" and not out.exists() and time.perf_counter() - start < 20


# --- 5. torch devices keyfill cannot use -----------------------------------------------------------------


@pytest.mark.parametrize("device", ["meta", "xla", "mps"])
@pytest.mark.parametrize("method", ["transformer", "gan"])
def test_devices_keyfill_cannot_use_are_a_usage_error(capsys, tmp_path, device, method):
    out = tmp_path / "o.usda"
    code, _, err = _clean_run(capsys, "complete", HUMAN_KEYS, "-o", out, "--method", method, "--runtime", "torch",
                              "--device", device)
    assert code == 2 and one_error_line(err) == (f"keyfill: error: --device {device!r} is not one keyfill runs on; "
                                                 "use cpu, cuda or cuda:N")
    assert not out.exists()


def test_training_on_a_device_keyfill_cannot_use_is_refused_before_the_corpus_is_read(capsys, tmp_path):
    # tests/data mixes frame rates, which reading it as a corpus refuses: the device is refused first
    code, _, err = _clean_run(capsys, "train", "gan", DATA, "-o", tmp_path / "m",
                              "--device", "meta", "--epochs", "1")
    assert code == 2 and "--device 'meta' is not one keyfill runs on" in one_error_line(err)
    assert not (tmp_path / "m").exists()


def test_a_gpu_index_beyond_the_gpus_is_a_usage_error(monkeypatch):
    import torch

    from keyfill.errors import UsageError
    from keyfill.learn.modelfile import torch_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert torch_device("cuda:0").index == 0
    with pytest.raises(UsageError, match="sees 1 CUDA GPU"):
        torch_device("cuda:3")


# --- 6. parents that form a cycle ------------------------------------------------------------------------


def _cycle(parents: list) -> None:
    parents[0], parents[1], parents[2] = 2, 0, 1  # 0 -> 2 -> 1 -> 0


@pytest.mark.parametrize("model", ["lamp", "bandai2-transformer", "bandai2-gan"])
def test_model_configs_whose_parents_form_a_cycle_are_refused(capsys, tmp_path, model):
    from keyfill.learn.installed_models import shipped

    src = shipped("lamp-arnn" if model == "lamp" else model)
    folder = tmp_path / "model"
    shutil.copytree(src, folder, ignore=shutil.ignore_patterns("model.onnx"))
    config = json.loads((folder / "config.json").read_text())
    _cycle(config["skeleton"]["parents"])
    (folder / "config.json").write_text(json.dumps(config))
    keys, method = (LAMP_KEYS, "arnn") if model == "lamp" else (HUMAN_KEYS, model.split("-")[1])
    out = tmp_path / "o.usda"
    code, _, err = _clean_run(capsys, "complete", keys, "-o", out, "--method", method, "--model", folder)
    line = one_error_line(err)
    assert code == 1 and str(folder) in line and "skeleton.parents[0] must be the index of an earlier joint" in line
    assert not out.exists()


def test_graphs_and_libraries_whose_parents_form_a_cycle_are_refused(capsys, tmp_path):
    pytest.importorskip("onnxruntime")
    onnx = pytest.importorskip("onnx")
    from keyfill.learn.installed_models import shipped

    graph = onnx.load(str(shipped("bandai2-transformer") / "model.onnx"))
    for prop in graph.metadata_props:
        if prop.key == "keyfill.config":
            config = json.loads(prop.value)
            _cycle(config["skeleton"]["parents"])
            prop.value = json.dumps(config)
    onnx.save(graph, str(tmp_path / "cycle.onnx"))
    out = tmp_path / "o.usda"
    code, _, err = _clean_run(capsys, "complete", HUMAN_KEYS, "-o", out, "--method", "transformer",
                              "--model", tmp_path / "cycle.onnx")
    line = one_error_line(err)
    assert code == 1 and "cycle.onnx" in line and "its parent must come before it" in line, line
    library = tmp_path / "library"
    library.mkdir()
    for f in shipped("bandai2-library").iterdir():
        if f.name != "library.json":
            (library / f.name).symlink_to(f)
    manifest = json.loads((shipped("bandai2-library") / "library.json").read_text())
    _cycle(manifest["skeleton"]["parents"])
    (library / "library.json").write_text(json.dumps(manifest))
    code, _, err = _clean_run(capsys, "complete", HUMAN_KEYS, "-o", out, "--method", "match", "--library", library)
    line = one_error_line(err)
    assert code == 1 and str(library) in line and "its parent must come before it" in line, line
    assert not out.exists()


# --- 4b. the other settings files: edit files and --config -----------------------------------------------


@pytest.mark.parametrize("kind", ["device", "fifo"])
def test_edit_files_and_configs_are_regular_files(capsys, tmp_path, kind):
    """/dev/zero read to its end fills the memory and a FIFO waits for a writer: an edit file and a training
    --config are read as a rig map is (files.read_regular)."""
    if kind == "device":
        path = Path("/dev/zero")
    else:
        path = tmp_path / "settings"
        os.mkfifo(path)
    curves = LAMP_KEYS.parents[1] / "edit" / "lamp_nod_curves.usda"
    out = tmp_path / "out.usda"
    start = time.perf_counter()
    code, stdout, err = _clean_run(capsys, "edit-tangents", curves, "--edit", path, "-o", out)
    line = one_error_line(err)
    assert code == 1 and str(path) in line and "the edit file must be a regular file" in line, line
    assert stdout == ""
    code, stdout, err = _clean_run(capsys, "train", "transformer", DATA, "-o", tmp_path / "m", "--config", path)
    line = one_error_line(err)
    assert code == 2 and str(path) in line and "the config must be a regular file" in line, line
    assert stdout == "" and not out.exists() and not (tmp_path / "m").exists() and time.perf_counter() - start < 20


@pytest.mark.parametrize("uri", ["/dev/zero", "../outside.bin", "fifo.bin"])
def test_a_batch_follows_a_gltf_uri_only_where_the_reader_does(capsys, tmp_path, uri):
    """Hashing a batch's inputs followed every buffer URI (absolute, ``../``, a FIFO): /dev/zero or a FIFO hung
    it. It now follows them as the reader does, and the input fails with the reader's own line."""
    src = tmp_path / "in"
    src.mkdir()
    assert run(capsys, "convert", CMU, src / "a.gltf")[0] == 0
    doc = json.loads((src / "a.gltf").read_text())
    doc["buffers"][0]["uri"] = uri
    (src / "a.gltf").write_text(json.dumps(doc))
    (tmp_path / "outside.bin").write_bytes((src / "a.bin").read_bytes())
    os.mkfifo(src / "fifo.bin")
    out = tmp_path / "out"
    start = time.perf_counter()
    code, _, err = _clean_run(capsys, "convert", src, "-o", f"{out}/", "--format", "bvh")
    assert code == 1 and time.perf_counter() - start < 20
    lines = err.strip().splitlines()
    assert lines[0].startswith(f"keyfill: error: {src / 'a.gltf'}: buffer 0") and "Traceback" not in err
    assert not (out / "a.bvh").exists()


def test_a_usd_layer_that_is_no_regular_file_is_one_line_not_a_hang(capsys, tmp_path):
    """A sublayer that is a FIFO hung USD's stage opening (no signal reaches it there); every layer a stage
    composes is checked first, in single and batch runs."""
    shot = tmp_path / "in" / "shot.usda"
    shot.parent.mkdir()
    shot.write_text('#usda 1.0\n(\n    subLayers = [@./fifo.usda@]\n)\n')
    os.mkfifo(shot.parent / "fifo.usda")
    start = time.perf_counter()
    code, _, err = _clean_run(capsys, "info", shot)
    assert code == 1 and "fifo.usda', which is not a regular file" in one_error_line(err)
    code, _, err = _clean_run(capsys, "convert", shot.parent, "-o", f"{tmp_path / 'out'}/", "--format", "bvh")
    assert code == 1 and "fifo.usda', which is not a regular file" in err.strip().splitlines()[0]
    assert time.perf_counter() - start < 20 and not (tmp_path / "out" / "shot.bvh").exists()


def test_a_batch_redoes_a_usd_output_whose_sublayer_changed(capsys, tmp_path):
    """The record's input digest covers the layers a USD stage composes, not only its root file."""
    src = tmp_path / "in"
    src.mkdir()
    assert run(capsys, "convert", CMU, tmp_path / "anim.usda")[0] == 0
    (src / "shot.usda").write_text(f'#usda 1.0\n(\n    subLayers = [@{tmp_path / "anim.usda"}@]\n)\n')
    out = f"{tmp_path / 'out'}/"
    assert run(capsys, "convert", src, "-o", out, "--format", "bvh", "--json")[0] == 0
    assert json.loads(run(capsys, "convert", src, "-o", out, "--format", "bvh", "--json")[1])["skipped"] == 1
    motion = io.load(tmp_path / "anim.usda")
    io.save(motion.replace(positions=motion.positions + 1.0), tmp_path / "anim.usda")
    code, stdout, _ = run(capsys, "convert", src, "-o", out, "--format", "bvh", "--json")
    assert code == 0 and json.loads(stdout)["redone"] == 1


@pytest.mark.parametrize("device", ["fifo", "/dev/null"])
def test_an_output_that_is_a_device_or_pipe_is_refused_not_replaced(capsys, tmp_path, device):
    """The atomic rename would replace it: as root, ``-o /dev/null`` made /dev/null a regular file (found by
    the option fuzzer's ``/dev/null`` paths). Standard output is ``-``."""
    if device == "fifo":
        target = tmp_path / "out.bvh"
        os.mkfifo(target)
    else:
        target = Path(device)
    before = os.stat(target)
    code, _, err = _clean_run(capsys, "convert", CMU, target, "--format", "bvh")
    assert code == 2 and "is a device or pipe, not a file; write to '-'" in one_error_line(err)
    after = os.stat(target)
    assert (after.st_mode, after.st_ino, after.st_rdev) == (before.st_mode, before.st_ino, before.st_rdev)
    if device == "fifo":
        assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bvh"]  # no temporary file beside it


@pytest.mark.parametrize("suffix", ["", ".bvh"])
def test_an_output_name_too_long_for_the_file_system_is_one_line(capsys, tmp_path, suffix):
    """Found by the option fuzzer: ``-o`` of 300 characters was an internal OSError (is_batch's is_dir, then the
    atomic writer's checks)."""
    out = tmp_path / ("x" * 300 + suffix)
    code, _, err = _clean_run(capsys, "complete", CMU, "--key-every", "2", "-o", out)
    line = one_error_line(err)
    assert code in (1, 2) and "internal error" not in line and str(out)[:40] in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [
    ("convert", "{long}.bvh", "{tmp}/o.bvh"),  # one input
    ("convert", CMU, "{long}", "-o", "{tmp}/o/"),  # make fuzz seed 20261205, case 12011: a batch's input
    ("complete", LAMP_KEYS, "{long}", "-o", "{tmp}/o/", "--method", "linear"),  # case 13937
    ("info", "{long}.glb"),
    ("edit-tangents", "{long}.usda", "--edit", "{long}.toml", "-o", "{tmp}/o.usda"),
])
def test_an_input_name_too_long_for_the_file_system_is_a_usage_error(capsys, tmp_path, args):
    """Found by the option fuzzer (seed 20261205): an input of 300 characters was an internal OSError wherever
    a path's kind was asked (Path.is_dir and is_file raise ENAMETOOLONG); now exit 2 naming the path, as a
    missing path is."""
    long = "x" * 300
    args = [str(a).replace("{long}", long).replace("{tmp}", str(tmp_path)) for a in args]
    code, _, err = _clean_run(capsys, *args)
    line = one_error_line(err)
    assert code == 2 and "internal error" not in line and long[:40] in line, line
    assert "name too long" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []
