"""``keyfill complete --feet lock|free`` and ``--ground``: defaults, the report, bad input."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run

from keyfill import io

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
HUMAN = EXAMPLES / "human" / "keys_15.usda"
LAMP = EXAMPLES / "lamp" / "keys.usda"


@pytest.mark.parametrize("method", ["cubic", "transformer", "gan"])
def test_the_default_leaves_the_feet_free(tmp_path, capsys, method):
    code, out, _ = run(capsys, "complete", HUMAN, "-o", tmp_path / "o.usda", "--method", method, "--json")
    assert code == 0 and "feet" not in json.loads(out)
    code, out, _ = run(capsys, "complete", HUMAN, "-o", tmp_path / "l.usda", "--method", method, "--feet", "lock",
                       "--json")
    assert code == 0 and json.loads(out)["feet"] == "lock"


def test_lock_holds_the_feet_and_keeps_the_keys(tmp_path, capsys):
    src = io.load(HUMAN)
    code, out, _ = run(capsys, "complete", HUMAN, "-o", tmp_path / "o.usda", "--method", "cubic", "--feet", "lock",
                       "--json")
    info = json.loads(out)
    assert code == 0 and info["feet"] == "lock" and info["contact_intervals"] > 0
    assert info["foot_skating_cm_s"]["after"] < 0.5 * info["foot_skating_cm_s"]["before"]
    filled = io.load(tmp_path / "o.usda")
    k = src.keys.frames
    np.testing.assert_allclose(filled.rotations[k], src.rotations[k], atol=1e-8)  # float32 in the USD file
    np.testing.assert_allclose(filled.positions[k], src.positions[k], atol=1e-6)
    code, _, _ = run(capsys, "complete", HUMAN, "-o", tmp_path / "f.usda", "--method", "cubic", "--feet", "free")
    free = io.load(tmp_path / "f.usda")
    assert not np.allclose(free.rotations, filled.rotations)  # locking changed the legs


def test_locked_keys_are_bit_identical_in_the_library():
    from keyfill.learn import registry
    from keyfill.learn.completion import CompleteOptions

    src = io.load(HUMAN)
    out = registry.complete(src, src.keys, "transformer", CompleteOptions(feet="lock"))
    assert out.info["feet"] == "lock"
    k = src.keys.frames
    np.testing.assert_array_equal(out.motion.rotations[k], src.rotations[k])
    np.testing.assert_array_equal(out.motion.positions[k], src.positions[k])


def test_feet_lock_on_a_skeleton_without_legs_is_one_line(tmp_path, capsys):
    code, _, err = run(capsys, "complete", LAMP, "-o", tmp_path / "o.usda", "--method", "cubic", "--feet", "lock")
    assert code == 1 and len(err.strip().splitlines()) == 1
    assert err.startswith("keyfill: error: --feet lock needs a skeleton with legs: ") and "thigh_l" in err
    assert not (tmp_path / "o.usda").exists()


def test_a_ground_that_is_no_number_is_a_usage_error(tmp_path, capsys):
    code, _, err = run(capsys, "complete", HUMAN, "-o", tmp_path / "o.usda", "--feet", "lock", "--ground", "low")
    assert code == 2 and "--ground" in err and not (tmp_path / "o.usda").exists()


def test_the_ground_moves_the_contacts(tmp_path, capsys):
    code, out, _ = run(capsys, "complete", HUMAN, "-o", tmp_path / "o.usda", "--feet", "lock", "--ground", "-1000",
                       "--json")
    assert code == 0 and json.loads(out)["contact_intervals"] == 0  # no foot is near a ground 10 m below
