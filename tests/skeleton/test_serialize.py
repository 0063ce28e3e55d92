"""Skeleton <-> dict/JSON serialisation is lossless and validates its input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.errors import FormatError
from mocapkit.skeleton import load_preset, preset_names, preset_options
from mocapkit.skeleton.serialize import (
    skeleton_from_dict,
    skeleton_from_json,
    skeleton_to_dict,
    skeleton_to_json,
)

_FIELDS = (
    "parents",
    "offsets_mm",
    "dof_joint",
    "dof_kind",
    "dof_axis",
    "lower",
    "upper",
    "bone_end_mm",
    "mass_kg",
    "com_fraction",
    "radii_mm",
)


@pytest.mark.parametrize("name", preset_names())
def test_json_round_trip_is_bit_exact(name: str) -> None:
    skel = load_preset(name, preset_options(name))
    text = skeleton_to_json(skel)
    back = skeleton_from_json(text)
    assert back.name == skel.name
    assert back.joint_names == skel.joint_names
    assert back.dof_names == skel.dof_names
    for f in _FIELDS:
        np.testing.assert_array_equal(getattr(back, f), getattr(skel, f), err_msg=f)
    assert back.canonical == skel.canonical


def test_json_is_strict_and_infinite_limits_become_null() -> None:
    skel = load_preset("zhang21")
    text = skeleton_to_json(skel)
    assert "Infinity" not in text and "NaN" not in text
    data = json.loads(text)
    # the root translations have no limits
    assert data["lower"][0] is None and data["upper"][0] is None
    assert np.isinf(skeleton_from_dict(data).lower[0])


def test_bad_documents_raise_format_error() -> None:
    data = skeleton_to_dict(load_preset("upper_stick"))
    with pytest.raises(FormatError, match="field 'format' should be"):
        skeleton_from_dict({**data, "format": "something"}, "x.json")
    missing = dict(data)
    del missing["offsets_mm"]
    with pytest.raises(FormatError, match="x.json: missing field 'offsets_mm'"):
        skeleton_from_dict(missing, "x.json")
    with pytest.raises(FormatError, match="unsupported skeleton format version"):
        skeleton_from_dict({**data, "version": 99})
    with pytest.raises(FormatError, match="not valid JSON"):
        skeleton_from_json("{not json", "y.json")
    with pytest.raises(FormatError, match="invalid skeleton"):
        skeleton_from_dict({**data, "parents": data["parents"][:-1]}, "x.json")
