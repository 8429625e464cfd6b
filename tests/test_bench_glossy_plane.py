"""bench/glossy_plane.py: the generated floor loads as the glTF it describes, and lobeview draws it
from its mirror pass (the case whose sun the mirror buffer loses: docs/measurements.md)."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.bench.glossy_plane import main, normal_map_texel


@pytest.mark.parametrize("tilt", [None, 30.0])
def test_generated_plane_loads_with_its_material_and_is_a_planar_reflector(tmp_path, tilt):
    from lobeview.scenes.analysis import analyse
    from lobeview.scenes.gltf_loader import load_gltf

    out = tmp_path / "plane.gltf"
    args = [str(out), "--roughness", "0.4", "--base", "0.05"] + ([] if tilt is None else ["--tilt", str(tilt)])
    assert main(args) == 0
    scene = load_gltf(out)
    (obj,) = scene.objects
    desc = scene.materials[obj.material].desc
    assert desc["roughness"] == pytest.approx(0.4) and desc["metallic"] == 0.0
    assert np.allclose(desc["base_color"], 0.05)
    np.testing.assert_allclose(obj.mesh.positions[:, 1], 0.0)
    assert np.ptp(obj.mesh.positions[:, 0]) == pytest.approx(2.0)
    textures = scene.materials[obj.material].textures
    if tilt is None:
        assert "normal" not in textures
    else:
        texel = np.asarray(textures["normal"].image)[0, 0, :3].astype(np.float64) / 255.0 * 2.0 - 1.0
        assert np.degrees(np.arctan2(texel[0], texel[2])) == pytest.approx(tilt, abs=0.5)
    (needs,) = analyse(scene).objects
    assert needs.reflector is not None  # alpha 0.16 <= MAX_MIRROR_ROUGHNESS: drawn from its mirror pass


def test_tilt_texel_and_bad_arguments(tmp_path):
    assert tuple(normal_map_texel(0.0)) == (128, 128, 255)
    with pytest.raises(SystemExit):
        main([str(tmp_path / "x.gltf"), "--roughness", "2"])
    with pytest.raises(SystemExit):
        main([str(tmp_path / "x.gltf"), "--tilt", "90"])
