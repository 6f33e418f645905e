"""Skeleton.to_json / from_json: the one JSON form of a skeleton (model folders record it)."""

import json
from pathlib import Path

import numpy as np
import pytest

from keyfill import io
from keyfill.errors import DataError
from keyfill.motion import Skeleton

DATA = Path(__file__).parent / "data"


def _skeleton() -> Skeleton:
    return io.load(min(DATA.glob("*.bvh"))).skeleton


def test_full_form_round_trips_through_json_text():
    skel = _skeleton()
    back = Skeleton.from_json(json.loads(json.dumps(skel.to_json())))
    assert back.names == skel.names
    np.testing.assert_array_equal(back.parents, skel.parents)
    np.testing.assert_array_equal(back.offsets, skel.offsets)  # float repr in JSON is exact
    assert back.channels == skel.channels
    assert (back.up_axis, back.meters_per_unit) == (skel.up_axis, skel.meters_per_unit)
    assert back.difference(skel) is None


def test_hierarchy_form_keeps_names_parents_offsets_only():
    skel = _skeleton()
    data = skel.to_json(hierarchy_only=True)
    assert sorted(data) == ["names", "offsets", "parents"]
    back = Skeleton.from_json(data)
    assert back.names == skel.names and back.channels == tuple(() for _ in skel.names)
    np.testing.assert_array_equal(back.offsets, skel.offsets)


@pytest.mark.parametrize("field, value", [("channels", [[1, 2, 3]]), ("channels", "XYZ"), ("up_axis", 1),
                                          ("meters_per_unit", "cm")])
def test_wrong_types_are_a_data_error(field, value):
    data = _skeleton().to_json()
    data[field] = value
    with pytest.raises(DataError):
        Skeleton.from_json(data)


def test_full_form_without_a_field_is_a_key_error():
    data = _skeleton().to_json()
    del data["up_axis"]
    with pytest.raises(KeyError):
        Skeleton.from_json(data)
