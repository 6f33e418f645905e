"""Bad model configs and output records: one ``keyfill: error:`` line naming the file and the field (issue 32).

The mutation test repeats the issue's experiment: copies of each shipped human model's ``config.json`` with one
value changed (its type, its sign, its size, or the key dropped), loaded and run on a short completion through
the CLI in this process; each must either complete or give exactly one error line, never a traceback or an
internal error. ``-m slow`` runs 150 copies per model; the default run a seeded subset.
"""

from __future__ import annotations

import copy
import json
import random
import shutil
from pathlib import Path

import pytest
from conftest import one_error_line, run

ROOT = Path(__file__).resolve().parents[1]
HUMAN_KEYS = ROOT / "examples" / "human" / "keys_15.usda"
LAMP_KEYS = ROOT / "examples" / "lamp" / "keys.usda"


def _shipped(method: str) -> Path:
    from keyfill.learn import registry

    path = registry.get(method).default_model()  # wherever the model distribution puts it (DEFAULT_MODEL)
    if path is None:
        pytest.skip(f"the shipped {method} model is not installed here")
    return path


def _nodes(value, path=()):
    yield path
    children = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in children:
        yield from _nodes(v, (*path, k))


def mutated(config: dict, rng: random.Random) -> tuple[dict, str]:
    """``config`` with one value (anywhere but the free-form ``training`` notes) changed: its type, its sign,
    its size, or its key dropped; and a description of the change."""
    out = copy.deepcopy(config)
    path = rng.choice([p for p in _nodes(out) if p and p[0] != "training"])
    parent = out
    for k in path[:-1]:
        parent = parent[k]
    key, value = path[-1], parent[path[-1]]
    op = rng.choice(["type", "sign", "size", "drop"])
    if op == "drop":
        parent.pop(key)
    elif op == "sign" and type(value) in (int, float):
        parent[key] = -value if value else -1
    elif op == "size" and isinstance(value, list):
        parent[key] = value[:-1] if value and rng.random() < 0.5 else value + value[:1]
    elif op == "size" and type(value) in (int, float):
        parent[key] = value * rng.choice([1000, 10**7, 0, 0.5])
    elif op == "size" and isinstance(value, str):
        parent[key] = value + value
    else:
        op = "type"
        parent[key] = rng.choice([None, "x", 1, -2.5, True, [], {}, [1, 2], {"a": 1}])
    return out, f"{op} {'.'.join(map(str, path))}"


def _mutation_cases(method: str, count: int, tmp_path: Path, capsys) -> dict:
    model = _shipped(method)
    config = json.loads((model / "config.json").read_text())
    rng = random.Random(f"issue 32 {method}")
    outcomes = {"completed": 0, "one line": 0}
    for i in range(count):
        changed, what = mutated(config, rng)
        folder = tmp_path / f"m{i}"
        folder.mkdir()
        (folder / "weights.safetensors").symlink_to(model / "weights.safetensors")  # no graph: the torch path
        (folder / "config.json").write_text(json.dumps(changed))
        code, _, err = run(capsys, "complete", HUMAN_KEYS, "--method", method, "--model", folder, "--keys", "0,15",
                           "--runtime", "torch", "-o", tmp_path / f"o{i}.usda")
        if code == 0:
            outcomes["completed"] += 1
        else:
            assert "internal error" not in one_error_line(err), what
            outcomes["one line"] += 1
    return outcomes


@pytest.mark.parametrize("method", ["transformer", "gan"])
def test_mutated_configs_of_the_shipped_models_complete_or_give_one_line(tmp_path, capsys, method):
    outcomes = _mutation_cases(method, 20, tmp_path, capsys)
    assert outcomes["one line"] >= 10, outcomes


@pytest.mark.slow
@pytest.mark.parametrize("method", ["transformer", "gan"])
def test_150_mutated_configs_per_shipped_model(tmp_path, capsys, method):
    outcomes = _mutation_cases(method, 150, tmp_path, capsys)
    assert sum(outcomes.values()) == 150 and outcomes["one line"] >= 100, outcomes


def _copy(model: Path, tmp_path: Path, change) -> Path:
    folder = tmp_path / "model"
    shutil.copytree(model, folder, ignore=shutil.ignore_patterns("model.onnx"))
    config = json.loads((folder / "config.json").read_text())
    change(config)
    (folder / "config.json").write_text(json.dumps(config))
    return folder


#: (model, change, the words of the one line)
CHANGES = [
    ("transformer", lambda c: c["architecture"].update(heads=-8),
     "config.json: architecture.heads must be a whole number from 1 to 256, got -8"),
    ("transformer", lambda c: c["architecture"].update(facing_axis=3), "architecture.facing_axis must be a string"),
    ("transformer", lambda c: c["architecture"].update(wings=2), "architecture.wings is not a setting of ModelConfig"),
    ("transformer", lambda c: c["architecture"].update(heads=7), "architecture: d_model 256 is not a multiple"),
    ("transformer", lambda c: c["skeleton"]["channels"][3].__setitem__(1, 5), "skeleton.channels[3][1] must be"),
    ("transformer", lambda c: c["statistics"]["pos_std"].pop(), "statistics.pos_std must be a list of 66"),
    ("transformer", lambda c: c.pop("folded_root"), "folded_root is missing"),
    ("gan", lambda c: c["ranges"]["orders"].__setitem__(2, ["ZXY"]), "ranges.orders[2] must be one of 'XYZ'"),
    ("gan", lambda c: c["ranges"]["driven"].__setitem__(2, 3000), "ranges.driven[2] must be a whole number from 1 to 21"),
    ("gan", lambda c: c["gan"]["widths"]["path"].__setitem__(4, 64000000), "gan.widths.path[4] must be a whole"),
    ("gan", lambda c: c["gan"].update(noise_dim="32"), "gan.noise_dim must be a whole number, got '32'"),
    ("gan", lambda c: c.update(fps=-30), "fps must be a number from"),
    ("gan", lambda c: c.update(stage=1), "stage must be one of 'path', 'full'"),
    ("gan", lambda c: c["skeleton"].update(up_axis=None), "skeleton.up_axis must be one of 'Y', 'Z'"),
    ("arnn", lambda c: c["normalizer"]["std"].__setitem__(0, -1), "normalizer.std[0] must be a number from 0"),
    ("arnn", lambda c: c.update(sizes={"hidden_size": "big"}), "sizes.hidden_size must be a positive integer"),
    ("arnn", lambda c: c["skeleton"]["names"].__setitem__(1, 7), "skeleton.names[1] must be a joint name"),
]


@pytest.mark.parametrize("method, change, words", CHANGES, ids=[f"{c[0]}-{c[2][:40]}" for c in CHANGES])
def test_each_field_is_checked_by_the_one_schema(tmp_path, method, change, words):
    from keyfill.errors import ModelError
    from keyfill.learn.modelfile import read_config

    folder = _copy(_shipped(method), tmp_path, change)
    with pytest.raises(ModelError) as caught:
        read_config(folder)
    assert words in str(caught.value) and str(folder / "config.json") in str(caught.value)
    assert caught.value.path == str(folder / "config.json")


def test_the_shipped_models_fit_the_schema():
    from keyfill.learn.config_schema import check_config

    for method in ("arnn", "transformer", "gan"):
        model = _shipped(method)
        check_config(json.loads((model / "config.json").read_text()), model / "config.json")


def test_a_field_added_to_a_settings_dataclass_is_checked_without_a_schema_edit(monkeypatch):
    import dataclasses

    from keyfill.learn import config_schema
    from keyfill.learn.transformer import config as tconfig

    @dataclasses.dataclass(frozen=True)
    class Later(tconfig.ModelConfig):
        new_width: int = 4

    monkeypatch.setattr(tconfig, "ModelConfig", Later)
    base = json.loads((_shipped("transformer") / "config.json").read_text())
    base["architecture"]["new_width"] = "four"
    with pytest.raises(config_schema.ModelError, match="architecture.new_width must be a whole number, got 'four'"):
        config_schema.check_config(base, "m/config.json")


def test_a_bad_model_config_with_json_is_the_error_object(tmp_path, capsys):
    folder = _copy(_shipped("transformer"), tmp_path, lambda c: c["architecture"].update(heads=-8))
    code, out, err = run(capsys, "complete", HUMAN_KEYS, "--method", "transformer", "--model", folder,
                         "-o", tmp_path / "o.usda", "--json")
    line = one_error_line(err)
    assert code == 1 and json.loads(out) == {"error": {
        "message": line.removeprefix("keyfill: error: "), "file": str(folder / "config.json"), "line": None,
        "exit_code": 1}}


# --- the record of an output folder ------------------------------------------------------------------


@pytest.fixture
def done_folder(tmp_path, capsys):
    (tmp_path / "in").mkdir()
    shutil.copy(LAMP_KEYS, tmp_path / "in" / "a.usda")
    code, _, err = run(capsys, "complete", tmp_path / "in", "-o", f"{tmp_path / 'out'}/")
    assert code == 0, err
    return tmp_path


RECORDS = [
    ("not json", b"not json", "not valid JSON at line 1"),
    ("a list", b"[]", "not a keyfill output record"),
    ("foreign", b'{"format": "something-else", "version": 1}', "not a keyfill output record"),
    ("nested", b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
    ("recipes a list", b'{"format": "keyfill-outputs", "version": 1, "recipes": [], "outputs": {}}',
     "its recipes are not"),
    ("entry of other types", (b'{"format": "keyfill-outputs", "version": 1, "recipes": {}, "outputs": {"a.usda": '
     b'{"input": 3, "input_sha256": "x", "recipe": "y", "output": "z"}}}'), "its outputs are not entries"),
    ("not utf-8", b'{"format": "keyfill-outputs\xff"}', "damaged or foreign record"),
]


@pytest.mark.parametrize("name, text, words", RECORDS, ids=[r[0] for r in RECORDS])
def test_a_damaged_or_foreign_record_is_one_line_naming_it(done_folder, capsys, name, text, words):
    record = done_folder / "out" / ".keyfill-outputs.json"
    record.write_bytes(text)
    before = (done_folder / "out" / "a.usda").read_bytes()
    code, out, err = run(capsys, "complete", done_folder / "in", "-o", f"{done_folder / 'out'}/", "--json")
    line = one_error_line(err)
    assert code == 2 and str(record) in line and words in line and "--force" in line
    error = json.loads(out)["error"]
    assert error["file"] == str(record) and error["exit_code"] == 2
    assert error["line"] == (1 if name == "not json" else None)
    assert (done_folder / "out" / "a.usda").read_bytes() == before  # nothing redone, nothing skipped silently
    code, _, err = run(capsys, "complete", done_folder / "in", "-o", f"{done_folder / 'out'}/", "--force")
    assert code == 0 and json.loads(record.read_text())["format"] == "keyfill-outputs", err
