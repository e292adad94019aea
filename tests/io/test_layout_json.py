"""Layout files: written and read back, and a file that is not one refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.io import read_layout_json, write_layout_json
from vibrofocus.layout import ArrayLayout
from vibrofocus.rigs import load_layout, make_rig


def test_a_layout_reads_back_equal_and_a_rig_takes_the_file(tmp_path):
    layout = ArrayLayout.grid((3, 2), 0.03, (2, 2), 0.01, guard_offset_m=9e-3, name="sleeve 3x2")
    path = write_layout_json(layout.to_dict(), tmp_path / "layout.json", about={"worst_contrast_db": 4.2})
    back = load_layout(path)
    assert back == layout and back.name == "sleeve 3x2"
    assert json.loads(path.read_text())["about"] == {"worst_contrast_db": 4.2}
    with make_rig("simulated", seed=1, layout=path) as rig:
        assert rig.layout == layout
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(layout.to_dict()))
    np.testing.assert_array_equal(ArrayLayout.from_dict(read_layout_json(bare)).actuators_xy, layout.actuators_xy)


@pytest.mark.parametrize(("content", "says"), [
    ("{", "is not UTF-8 JSON"),
    ('{"format": "vibrofocus layout", "version": 2, "layout": {}}', "version 2"),
    ('{"format": "vibrofocus layout", "version": 1, "layout": {"actuators_xy": [[0, 0]]}}', "'locations_xy'"),
    ("[1, 2]", "must be a JSON object"),
    ('{"actuators_xy": [["a", 0]], "locations_xy": [[0, 0]]}', "does not describe an array layout"),
])
def test_a_file_that_is_not_a_layout_is_refused_naming_why(tmp_path, content, says):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ValidationError, match=says):
        load_layout(path)
