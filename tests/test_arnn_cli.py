"""``keyfill train arnn``, ``keyfill complete --method arnn`` and ``keyfill evaluate`` (keys protocol) end to end."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from conftest import DATA

from keyfill import io
from keyfill.characters.lamp import from_variables, to_variables
from keyfill.cli.main import main
from keyfill.learn.modelfile import CONFIG, WEIGHTS
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """A 'keyfill simulate'-style folder with the 12 simulated sequences of tests/data/lamp_hops_seed1.npz."""
    folder = tmp_path_factory.mktemp("hops")
    d = np.load(DATA / "lamp_hops_seed1.npz")
    lines = []
    for run, (values, keys, name) in enumerate(zip(d["values"], d["keys"], d["names"])):
        io.save(from_variables(values, 60.0, keys=Keys(keys)), folder / f"{name}.usda")
        lines.append(json.dumps({"id": str(name), "file": f"{name}.usda", "run": run, "keys": keys.tolist()}))
    (folder / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    return folder


@pytest.fixture(scope="module")
def model(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("models") / "lamp"
    assert main(["-q", "train", "arnn", str(dataset), "-o", str(out), "--epochs", "2", "--batch-size", "5",
                 "--checkpoint-every", "1"]) == 0
    return out


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_train_writes_model_log_and_checkpoint(model, dataset, capsys, tmp_path):
    config = json.loads((model / CONFIG).read_text())
    assert config["kind"] == "arnn" and config["training"]["train_sequences"] == 9
    assert config["training"]["settings"]["epochs"] == 2 and len(config["normalizer"]["mean"]) == 6
    rows = (model.parent / "lamp.log.jsonl").read_text().splitlines()
    assert [json.loads(r)["epoch"] for r in rows] == [1, 2]
    assert (model.parent / "lamp.checkpoint.pt").is_file()
    # --resume of a finished run only rewrites the model; same bytes
    before = (model / WEIGHTS).read_bytes()
    code, out, _ = run(capsys, "train", "arnn", dataset, "-o", model, "--epochs", 2, "--batch-size", 5,
                       "--checkpoint-every", 1, "--resume", "--json")
    assert code == 0 and json.loads(out)["epochs"] == 2 and (model / WEIGHTS).read_bytes() == before


def test_complete_hits_keys_exactly_and_reports_the_residual(model, dataset, capsys, tmp_path):
    src = dataset / "seq_00025.usda"
    dst = tmp_path / "filled.usda"
    code, out, _ = run(capsys, "complete", src, "-o", dst, "--method", "arnn", "--model", model, "--json")
    assert code == 0
    info = json.loads(out)
    assert info["exact_keys"] is True and info["arch"] == "arnn"
    assert info["key_residual_removed"]["position_m"] > 1e-4  # a 2-epoch model misses its keys ...
    truth, filled = io.load(src), io.load(dst)
    k = truth.keys.frames
    v_truth, v_filled = to_variables(truth), to_variables(filled)
    assert np.abs(v_filled[k] - v_truth[k]).max() < 1e-6  # ... and the correction puts them back
    assert np.abs(v_filled - v_truth).max() > 1e-3  # in-betweens are the network's, not a copy
    code, out, _ = run(capsys, "complete", src, "-o", tmp_path / "raw.usda", "--method", "arnn", "--model", model,
                       "--no-exact-keys", "--json")
    raw = to_variables(io.load(tmp_path / "raw.usda"))
    assert code == 0 and json.loads(out)["key_residual_left"]["position_m"] > 1e-4
    assert np.abs(raw[k] - v_truth[k]).max() > 1e-4


def test_complete_any_length_and_key_spacing(model, dataset, capsys, tmp_path):
    """Timing edits (Figure 10): keys moved, and frames before the first / after the last key hold those keys."""
    src = dataset / "seq_00025.usda"
    dst = tmp_path / "timing.usda"
    code, _, _ = run(capsys, "complete", src, "-o", dst, "--method", "arnn", "--model", model,
                     "--keys", "3,7,20,40,60,80")
    assert code == 0
    filled = to_variables(io.load(dst))
    truth = to_variables(io.load(src))
    assert filled.shape == (87, 6)
    assert np.allclose(filled[:3], truth[3]) and np.allclose(filled[81:], truth[80])
    assert np.abs(filled[[3, 7, 20, 40, 60, 80]] - truth[[3, 7, 20, 40, 60, 80]]).max() < 1e-6


def test_model_for_another_skeleton_is_refused(model, capsys, tmp_path):
    code, _, err = run(capsys, "complete", DATA / "cmu_02_03_cgspeed_first4frames.bvh", "-o", tmp_path / "x.bvh",
                       "--keys", "0,3", "--method", "arnn", "--model", model)
    assert code == 1
    assert err.strip().startswith("keyfill: error:") and "made for another skeleton (4 joints vs 31; the first that differs is joint 0" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "x.bvh").exists()
    code, _, err = run(capsys, "complete", DATA / "cmu_02_03_cgspeed_first4frames.bvh", "-o", tmp_path / "x.bvh",
                       "--keys", "0,3", "--method", "arnn")
    assert code == 2 and "the built-in ARNN model serves the hopping lamp" in err


def test_tampered_model_is_refused_without_executing_anything(model, dataset, capsys, tmp_path):
    src = dataset / "seq_00025.usda"
    bad = tmp_path / "bad"
    shutil.copytree(model, bad)
    marker = tmp_path / "executed"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    torch.save({"gru1.weight_ih_l0": Evil()}, bad / WEIGHTS)  # a pickle disguised as weights
    code, _, err = run(capsys, "complete", src, "-o", tmp_path / "o.usda", "--method", "arnn", "--model", bad)
    assert code == 1 and "damaged or truncated weights" in err and not marker.exists()
    # truncated weights
    data = (model / WEIGHTS).read_bytes()
    (bad / WEIGHTS).write_bytes(data[: len(data) // 3])
    code, _, err = run(capsys, "complete", src, "-o", tmp_path / "o.usda", "--method", "arnn", "--model", bad)
    assert code == 1 and "damaged or truncated weights" in err
    # weights of another shape
    shutil.copy(model / WEIGHTS, bad / WEIGHTS)
    config = json.loads((model / CONFIG).read_text())
    (bad / CONFIG).write_text(json.dumps({**config, "sizes": {"hidden_size": 50}}))
    code, _, err = run(capsys, "complete", src, "-o", tmp_path / "o.usda", "--method", "arnn", "--model", bad)
    assert code == 1 and "the weights do not fit the model's configuration" in err
    # a config without normalisation statistics
    (bad / CONFIG).write_text(json.dumps({k: v for k, v in config.items() if k != "normalizer"}))
    code, _, err = run(capsys, "complete", src, "-o", tmp_path / "o.usda", "--method", "arnn", "--model", bad)
    assert code == 1 and "config.json: normalizer is missing" in err
    # not a keyfill model at all
    (tmp_path / "plain").mkdir()
    code, _, err = run(capsys, "complete", src, "-o", tmp_path / "o.usda", "--method", "arnn", "--model",
                       tmp_path / "plain")
    assert code == 1 and "not a keyfill model" in err
    assert not (tmp_path / "o.usda").exists()


@pytest.mark.parametrize("keys, message", [("5", "at least 2 keys are needed, got 1"),
                                           ("10,5", "keys must be in increasing order: 10 comes before 5")])
def test_bad_keys(model, dataset, capsys, tmp_path, keys, message):
    code, _, err = run(capsys, "complete", dataset / "seq_00025.usda", "-o", tmp_path / "o.usda", "--method", "arnn",
                       "--model", model, "--keys", keys)
    assert code == 2 and message in err and not (tmp_path / "o.usda").exists()


def test_training_data_folder_without_sequences(capsys, tmp_path):
    code, _, err = run(capsys, "train", "arnn", tmp_path, "-o", tmp_path / "m")
    assert code == 1 and "holds no simulated sequences" in err
    (tmp_path / "manifest.jsonl").write_text("")
    code, _, err = run(capsys, "train", "arnn", tmp_path, "-o", tmp_path / "m")
    assert code == 1 and "holds no simulated sequences yet" in err and not (tmp_path / "m").exists()


def test_bad_training_options(dataset, capsys, tmp_path):
    code, _, err = run(capsys, "train", "arnn", dataset, "-o", tmp_path / "m", "--epochs", 0)
    assert code == 2 and "--epochs must be at least 1" in err
    code, _, err = run(capsys, "train", "arnn", dataset, "-o", tmp_path / "m", "--key-weight", -1)
    assert code == 2 and "--key-weight must be 0 or more, got -1.0" in err
    code, _, err = run(capsys, "train", "arnn", dataset, "-o", tmp_path / "m", "--resume")
    assert code == 2 and "--resume: no checkpoint" in err
    code, _, err = run(capsys, "train", "arnn", dataset, "-o", tmp_path / "missing" / "m")
    assert code == 2 and "does not exist" in err
    (tmp_path / "notes").mkdir()
    code, _, err = run(capsys, "train", "arnn", dataset, "-o", tmp_path / "notes")
    assert code == 2 and "is not a keyfill model; refusing to replace it" in err


def test_evaluate_keys_protocol(model, dataset, capsys):
    code, out, _err = run(capsys, "evaluate", model, dataset, "--json")
    assert code == 0
    res = json.loads(out)
    assert res["protocol"] == "keys" and res["test_sequences"] == 2
    rows = res["results"]
    assert set(rows) == {f"arnn ({model})", f"arnn ({model}) + exact keys", "linear", "cubic", "cubic-variables"}
    assert rows["cubic"]["all_keys"]["key"] == 0.0 and rows[f"arnn ({model}) + exact keys"]["all_keys"]["key"] < 1e-12
    for r in rows.values():
        for cond in ("all_keys", "deleted_keys"):
            assert r[cond]["total"] == pytest.approx(r[cond]["key"] + r[cond]["frame"])
    code, out, _ = run(capsys, "evaluate", "cubic", dataset, "--no-baselines")
    assert code == 0 and out.splitlines()[2].startswith("cubic") and len(out.splitlines()) == 3
