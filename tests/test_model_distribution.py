"""keyfill's wheel is MIT only; the CC BY-NC human models are their own distribution (models/bandai).

keyfill finds installed model distributions through the ``keyfill.models`` entry points
(:mod:`keyfill.learn.installed_models`) and, when none gives the model a command needs, says how to
get it: one line, nothing written, also as the JSON error object.
"""

from __future__ import annotations

import json
import tomllib
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest
from conftest import one_error_line, run

from keyfill.learn import installed_models

ROOT = Path(__file__).resolve().parents[1]
BANDAI = ROOT / "models" / "bandai"
EXAMPLES = ROOT / "examples" / "human"


def _package_data() -> list[Path]:
    """The files under keyfill/ that pyproject.toml's package-data globs put into the wheel."""
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert set(globs) == {"keyfill"}
    return sorted({p for g in globs["keyfill"] for p in (ROOT / "keyfill").glob(g) if p.is_file()})


def test_keyfill_package_data_holds_no_bandai_model_and_no_non_commercial_file():
    files = _package_data()
    assert files, "the globs match nothing: the lamp model would be missing from the wheel"
    rel = [p.relative_to(ROOT).as_posix() for p in files]
    assert not [r for r in rel if "bandai" in r.lower()]
    model_folders = {p.parent.name for p in files if p.name == "weights.safetensors"}
    assert model_folders == {"lamp-arnn"}  # trained on keyfill's own simulated hops: MIT
    for p in (ROOT / "keyfill").rglob("*"):  # nothing under keyfill/ carries the CC BY-NC licence text
        if p.is_file() and p.suffix not in {".py", ".pyc", ".safetensors", ".onnx"}:
            assert b"Attribution-NonCommercial" not in p.read_bytes(), p


def test_the_bandai_distribution_names_each_model_folder_with_its_licence_and_card():
    project = tomllib.loads((BANDAI / "pyproject.toml").read_text())["project"]
    assert project["license"] == "CC-BY-NC-4.0" and not project["dependencies"]
    assert "Attribution-NonCommercial 4.0 International" in (BANDAI / "LICENSE").read_text()
    entries = project["entry-points"][installed_models.GROUP]
    assert set(entries) == {"bandai2-transformer", "bandai2-gan", "bandai2-gan-partial", "bandai2-library"}
    for name, target in entries.items():
        folder = BANDAI / target.split(":")[0] / name
        # a model's weights and its corpus's pose index (the guard's); a library's manifest
        own = {"library.json"} if name.endswith("-library") else {"config.json", "weights.safetensors", "pose_index.npz"}
        assert own | {"LICENSE", "MODEL_CARD.md"} <= {p.name for p in folder.iterdir()}
        card = folder / "MODEL_CARD.md"
        for link in ("../../../../docs/transformer.md", "../../../../docs/gan.md", "../../../../docs/match.md"):
            if link in card.read_text():
                assert (folder / link).resolve().is_file()


def test_installed_reads_entry_points_and_leaves_out_broken_ones(monkeypatch, tmp_path):
    eps = [EntryPoint("good", "tempfile:tempdir", installed_models.GROUP),
           EntryPoint("broken", "no_such_module_here:X", installed_models.GROUP),
           EntryPoint("not-a-path", "os:getcwd", installed_models.GROUP)]  # a function, not a path
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    # the entry points as keyfill reads them (entry_points.txt files, without importlib.metadata)
    monkeypatch.setattr(installed_models, "entry_points",
                        lambda group: [(e.name, e.value) for e in eps if e.group == group])
    found = installed_models.installed.__wrapped__()
    assert found == {"good": tmp_path}


def test_lamp_model_is_inside_keyfill():
    from keyfill.learn.arnn.model import DEFAULT_MODEL

    assert DEFAULT_MODEL == installed_models.BUILTIN / "lamp-arnn" and DEFAULT_MODEL.is_dir()


@pytest.fixture
def no_model_distribution(monkeypatch):
    """As after ``pip install .`` alone: no distribution gives the human models."""
    from keyfill.learn.gan import model as gan
    from keyfill.learn.transformer import model as transformer

    monkeypatch.setattr(installed_models, "installed", dict)
    for module, name in ((gan, "DEFAULT_MODEL"), (gan, "PARTIAL_MODEL"), (transformer, "DEFAULT_MODEL")):
        monkeypatch.setattr(module, name, None)


@pytest.mark.parametrize("method,example", [("transformer", "keys_15.usda"), ("gan", "keys.usda")])
def test_without_the_model_distribution_complete_says_how_to_get_it(capsys, tmp_path, no_model_distribution,
                                                                    method, example):
    out = tmp_path / "x.bvh"
    code, stdout, err = run(capsys, "complete", EXAMPLES / example, "--method", method, "-o", out)
    line = one_error_line(err)
    assert code == 1 and not out.exists() and not stdout
    assert line.startswith(f"keyfill: error: the shipped {method} models are not installed: they are CC BY-NC 4.0")
    assert "pip install ./models/bandai" in line and "or give --model FOLDER" in line
    code, stdout, err = run(capsys, "complete", EXAMPLES / example, "--method", method, "-o", out, "--json")
    assert code == 1 and not out.exists()
    error = json.loads(stdout)["error"]
    assert error["exit_code"] == 1 and error["message"] == one_error_line(err).removeprefix("keyfill: error: ")


def test_without_the_model_distribution_a_batch_fails_with_one_line(
        capsys, tmp_path, no_model_distribution):
    import shutil

    clips = tmp_path / "clips"
    clips.mkdir()
    shutil.copy(EXAMPLES / "keys_15.usda", clips / "a.usda")
    code, _, err = run(capsys, "complete", clips, "--method", "transformer", "-o", tmp_path / "out")
    assert code == 1 and "pip install ./models/bandai" in one_error_line(err)
    assert not list(tmp_path.glob("out/*.usda"))


def test_without_the_model_distribution_info_and_help_still_work(capsys, no_model_distribution):
    code, out, _ = run(capsys, "info", EXAMPLES / "keys.usda", "--rig")
    assert code == 0
    assert "transformer: no: its shipped models are not installed" in out and "pip install ./models/bandai" in out
    code, out, _ = run(capsys, "complete", "--help")
    assert code == 0 and "transformer" in out


def test_make_installs_the_model_distribution_editable():
    makefile = (ROOT / "Makefile").read_text()
    rule = makefile[makefile.index("$(DEMO_STAMP):"):makefile.index("@touch $(DEMO_STAMP)")]  # test's STAMP needs it
    assert "-e ./models/bandai" in rule and "models/bandai/pyproject.toml" in rule.splitlines()[0]


def test_without_the_model_distribution_export_of_the_method_name_says_how_to_get_it(capsys, tmp_path,
                                                                                     no_model_distribution):
    code, _, err = run(capsys, "export", "transformer", "-o", tmp_path / "t.onnx")
    line = one_error_line(err)
    assert code == 1 and not (tmp_path / "t.onnx").exists()
    assert "pip install ./models/bandai" in line and line.endswith(
        "or give a model folder of your own instead (train one with 'keyfill train transformer')")
