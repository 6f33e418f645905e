"""Model files: round trip, atomic replacement, and refusal of anything not an intact keyfill model."""

import json
import os
import stat

import numpy as np
import pytest
import torch
from conftest import DATA

from keyfill.errors import ModelError
from keyfill.io import bvh
from keyfill.learn.modelfile import (
    CONFIG,
    WEIGHTS,
    check_skeleton,
    load_model,
    load_state,
    save_model,
)


@pytest.fixture
def skeleton():
    return bvh.read(DATA / "cmu_02_03_cgspeed_first4frames.bvh").skeleton


def _net():
    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Linear(4, 3), torch.nn.Linear(3, 2))


def test_round_trip_and_replace(tmp_path, skeleton):
    net = _net()
    path = tmp_path / "m"
    save_model(path, "toy", net.state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True), "hidden": 3})
    tensors, config = load_model(path, kind="toy")
    assert config["hidden"] == 3 and config["kind"] == "toy" and config["format"] == "keyfill-model"
    other = torch.nn.Sequential(torch.nn.Linear(4, 3), torch.nn.Linear(3, 2))
    load_state(other, tensors, path)
    x = torch.randn(5, 4)
    assert torch.equal(other(x), net(x))
    # Replacing keeps exactly one model and no temporary folders.
    save_model(path, "toy", net.state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True), "hidden": 4})
    assert load_model(path / CONFIG)[1]["hidden"] == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]


def test_model_files_get_the_modes_of_new_files(tmp_path, skeleton):
    umask = os.umask(0o022)
    try:
        path = save_model(tmp_path / "m", "toy", _net().state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True)})
    finally:
        os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o755
    assert {p.name: stat.S_IMODE(p.stat().st_mode) for p in path.iterdir()} == {CONFIG: 0o644, WEIGHTS: 0o644}


def test_refuses_other_skeleton_and_kind(tmp_path, skeleton):
    save_model(tmp_path / "m", "toy", _net().state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True)})
    _, config = load_model(tmp_path / "m")
    check_skeleton(config, skeleton)
    other = bvh.read(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton
    with pytest.raises(ModelError, match="made for another skeleton .31 joints vs 55"):
        check_skeleton(config, other)
    moved = skeleton.replace(offsets=skeleton.offsets + np.eye(3)[0] * 5)
    with pytest.raises(ModelError, match="different rest offset"):
        check_skeleton(config, moved)
    with pytest.raises(ModelError, match="a 'toy' model, not a 'arnn' model"):
        load_model(tmp_path / "m", kind="arnn")


def test_refuses_foreign_damaged_and_truncated_files(tmp_path, skeleton):
    with pytest.raises(ModelError, match="no such model"):
        load_model(tmp_path / "missing")
    (tmp_path / "plain").mkdir()
    with pytest.raises(ModelError, match="not a keyfill model"):
        load_model(tmp_path / "plain")
    (tmp_path / "plain" / CONFIG).write_text(json.dumps({"hello": 1}))
    with pytest.raises(ModelError, match="not a keyfill model"):
        load_model(tmp_path / "plain")

    save_model(tmp_path / "m", "toy", _net().state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True)})
    w = tmp_path / "m" / WEIGHTS
    data = w.read_bytes()
    w.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelError, match="damaged or truncated weights"):
        load_model(tmp_path / "m")
    # A pickle disguised as weights is refused without being executed.
    marker = tmp_path / "executed"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    torch.save({"x": Evil()}, w)
    with pytest.raises(ModelError, match="damaged or truncated weights"):
        load_model(tmp_path / "m")
    assert not marker.exists()


def test_weights_that_do_not_fit(tmp_path, skeleton):
    save_model(tmp_path / "m", "toy", _net().state_dict(), {"skeleton": skeleton.to_json(hierarchy_only=True)})
    tensors, _ = load_model(tmp_path / "m")
    with pytest.raises(ModelError, match="do not fit"):
        load_state(torch.nn.Linear(4, 2), tensors, tmp_path / "m")


def test_a_config_changed_on_disk_is_read_again(tmp_path, skeleton):
    """read_config skips only the schema check of bytes it passed before: a config edited in place (same size,
    within one clock tick) is read as it now is, and one damaged after a good read is refused."""
    from keyfill.learn.modelfile import read_config

    path = save_model(tmp_path / "m", "toy", _net().state_dict(),
                      {"skeleton": skeleton.to_json(hierarchy_only=True), "hidden": 3})
    assert read_config(path)["hidden"] == 3
    read_config(path)["hidden"] = 99  # each call gives a config of its own
    assert read_config(path)["hidden"] == 3
    text = (path / CONFIG).read_text()
    (path / CONFIG).write_text(text.replace('"hidden": 3', '"hidden": 4'))
    assert read_config(path)["hidden"] == 4
    (path / CONFIG).write_text(text.replace('"format"', '"f0rmat"'))
    with pytest.raises(ModelError, match="not a keyfill model"):
        read_config(path)
