"""keyfill's own USD customData dictionaries of the wrong shape: one line naming the file and the field (issue 32).

Each case is the shipped lamp curves file with one field of one dictionary changed by hand (its type, or the
field removed); ``keyfill info`` (the motion) and ``keyfill edit-tangents`` (the curves) must give one
``keyfill: error:`` line, and with ``--json`` the error object naming the file.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import one_error_line, run

CURVES = Path(__file__).resolve().parents[1] / "examples" / "edit" / "lamp_nod_curves.usda"
EDIT = CURVES.parent / "lamp_lift.toml"

#: (name, the text of the field in CURVES, its replacement, the words the error must hold)
CASES = [
    ("curves version a string", 'int version = 1', 'string version = "1"', "version must be an integer"),
    ("curves version a list", 'int version = 1', 'int[] version = [1]', "version must be an integer"),
    ("curves version negative", 'int version = 1', 'int version = -1', "version must be an integer of at least 0"),
    ("curves version missing", 'int version = 1', '', "has no 'version'"),
    ("curves layout a list", 'string layout = "keyfill.curves"', 'string[] layout = ["keyfill.curves"]',
     "not a keyfill curves file"),
    ("curve joint an int", 'string joint = "base"', 'int joint = 3', "joint must be a string, got 3"),
    ("curve channel missing", 'string channel = "Xposition"', '', "has no 'channel'"),
    ("curve unit a double", 'string unit = "radians"', 'double unit = 1.5', "unit must be a string"),
    ("knot broken a string", '{ bool broken = 0 }', '{ string broken = "no" }', "broken must be a bool"),
    ("skeleton names ints", 'string[] names = ["base", "leg", "neck", "head"]', 'int[] names = [1, 2, 3, 4]',
     "names must be a list of strings"),
    ("skeleton channels a string", ('string[] channels = ["Xposition Yposition Zrotation", "Zrotation", '
     '"Zrotation", "Zrotation"]'), 'string channels = "Zrotation"', "channels must be a list of strings"),
    ("skeleton keys doubles", 'int[] keys = [0, 10, 20, 30]', 'double[] keys = [0, 10.5]',
     "keys must be a list of integers"),
    ("skeleton end sites ints", 'int[] endSiteJoints = [3]', 'string endSiteJoints = "3"',
     "endSiteJoints must be a list of integers"),
    ("skeleton end site offsets", 'double3[] endSiteOffsets = [(0, 0.12, 0)]', 'double[] endSiteOffsets = [0.12]',
     "endSiteOffsets must be a list of 3-vectors"),
    ("skeleton key content an int", 'int[] keys = [0, 10, 20, 30]', ('int[] keys = [0, 10, 20, 30]\n'
     '                int keyGiven = 2'), "keyGiven must be a string"),
    ("skeleton dictionary a string", 'dictionary keyfill = {\n                string[] channels',
     'string keyfill = "x"\n            dictionary other = {\n                string[] channels',
     "customData keyfill must be a dictionary"),
]


def _changed(tmp_path: Path, old: str, new: str) -> Path:
    text = CURVES.read_text()
    assert text.count(old) >= 1, old
    path = tmp_path / "bad.usda"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("name, old, new, words", CASES, ids=[c[0] for c in CASES])
def test_a_bad_custom_data_field_is_one_line_naming_it(tmp_path, capsys, name, old, new, words):
    path = _changed(tmp_path, old, new)
    code, _, err = run(capsys, "edit-tangents", path, "--edit", EDIT, "-o", tmp_path / "out.usda")
    line = one_error_line(err)
    assert code == 1 and str(path) in line and words in line, line
    assert not (tmp_path / "out.usda").exists()


@pytest.mark.parametrize("name, old, new, words", [c for c in CASES if c[0].startswith("skeleton")],
                         ids=[c[0] for c in CASES if c[0].startswith("skeleton")])
def test_the_motion_reader_checks_the_skeleton_dictionary(tmp_path, capsys, name, old, new, words):
    path = _changed(tmp_path, old, new)
    code, _, err = run(capsys, "info", path)
    assert code == 1 and words in one_error_line(err)


def test_a_bad_field_with_json_is_the_error_object(tmp_path, capsys):
    path = _changed(tmp_path, 'int version = 1', 'string version = "1"')
    code, out, err = run(capsys, "info", path, "--json")
    assert code == 1
    line = one_error_line(err)
    error = json.loads(out)["error"]
    assert error == {"message": line.removeprefix("keyfill: error: "), "file": str(path), "line": None,
                     "exit_code": 1}
    assert "version must be an integer" in error["message"]


def test_the_checker_accepts_what_keyfill_writes(tmp_path):
    from keyfill.io import usd_curves

    curves = usd_curves.read(CURVES)
    usd_curves.save(curves, tmp_path / "again.usda")
    again = usd_curves.read(tmp_path / "again.usda")
    assert again.controls == curves.controls and (again.values == curves.values).all()
