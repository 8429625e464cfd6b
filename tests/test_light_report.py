"""The cube-map build's report of the bright sources each object's cube map holds as cap lights
(viewer/cube_bake.py light_report; issue 39 item 6: which lights each object sees)."""

from __future__ import annotations

import numpy as np

from lobeview.materials.cap_lights import CapLight
from lobeview.viewer.cube_bake import light_report


def _cap(radius_degrees: float) -> CapLight:
    return CapLight(np.array([0.0, 1.0, 0.0]), float(np.cos(np.radians(radius_degrees))), np.array([50.0, 50.0, 50.0]))


def test_objects_with_lights_are_named_with_count_and_radii():
    text = light_report([("floor", [_cap(0.5), _cap(11.0)]), ("wall", []), ("sphere", [_cap(3.0)])])
    assert text.startswith("[lights] bright sources as cap lights in 2 of 3 cube maps: ")
    assert "floor 2 (0.5-11.0 deg), sphere 1 (3.0 deg)" in text  # most lights first
    assert "wall" not in text


def test_no_lights_and_long_lists():
    assert light_report([("a", []), ("b", [])]) == "[lights] no bright source in any of the 2 cube maps: no cap lights"
    many = [(f"object {k}", [_cap(1.0)]) for k in range(11)]
    text = light_report(many, shown=8)
    assert text.count("(1.0 deg)") == 8 and text.endswith(", and 3 more")
