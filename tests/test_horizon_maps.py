"""Specular self-occlusion per lightmap texel (scenes/horizon_maps.py): the traced map against the
wall's exact horizon, its cache, and the shaders reading it at the lightmap coordinate."""

from __future__ import annotations

import numpy as np
import pytest
from test_self_visibility import _grid, assert_floor_ratios_follow, floor_occlusion_ratios

from lobeview.scenes.horizon_maps import lightmap_horizon_map, lightmap_images, lightmap_objects, texel_horizons
from lobeview.scenes.self_visibility import MAP_HORIZON_SECTORS, horizon_frame

MAP = 64  # lightmap texels a side


def _corner_scene(lightmap_value: float = np.pi):
    """A floor 3 x 2 with a wall 1 high and 3 wide at its back (2 x 2 cells each), one object, a metal of base colour
    0.5 (no diffuse), and a lightmap over TEXCOORD_1: the floor's chart the atlas' left half, the
    wall's the right half."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.meshes import merge_meshes
    from lobeview.scenes.scene import Lightmap, Scene, SceneMaterial, SceneObject

    # two triangles a side: horizons at the vertices, interpolated, would be far from the texels'
    floor = _grid((-1.5, 0.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, -2.0), 2)  # normal +y
    wall = _grid((-1.5, 0.0, -1.0), (3.0, 0.0, 0.0), (0.0, 1.0, 0.0), 2)  # normal +z
    mesh = merge_meshes([floor, wall], "corner")
    # inset by a texel, so that the two charts' bilinear reads never mix
    inset = 1.0 / MAP
    scale = [0.5 - 2 * inset, 1.0 - 2 * inset]
    uv1 = np.concatenate([floor.uvs * scale + inset, [0.5, 0.0] + wall.uvs * scale + inset]).astype(np.float32)
    metal = validate({"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 1.0, "roughness": 0.05})
    lightmap = Lightmap(np.full((MAP, MAP, 3), lightmap_value, np.float32), tex_coord=1)
    scene = Scene([SceneObject("corner", mesh, 0, uv1=uv1)], [SceneMaterial("metal", metal, lightmap=lightmap)])
    scene.objects[0].planar_reflector = False
    return scene, floor


def _wall_horizon_per_sector(point: np.ndarray) -> np.ndarray:
    """The exact horizon sine per sector at a floor point (x, 0, z) before the wall (z = -1, 0 <= y
    <= 1, |x| <= 1.5): the mean over each sector of the wall top's elevation sine, 0 where the
    azimuth misses the wall (quadrature, the frame of horizon_frame about +y)."""
    tangent, bitangent = horizon_frame(np.array([0.0, 1.0, 0.0]))
    phi = (np.arange(MAP_HORIZON_SECTORS * 400) + 0.5) / (MAP_HORIZON_SECTORS * 400) * 2.0 * np.pi
    toward = np.cos(phi)[:, None] * tangent + np.sin(phi)[:, None] * bitangent
    to_wall = -toward[:, 2]
    distance = (point[2] + 1.0) / np.maximum(to_wall, 1e-12)  # along the floor to the wall's plane
    lateral = np.abs(point[0] + distance * toward[:, 0])
    hit = (to_wall > 0.0) & (lateral <= 1.5)
    sin_top = np.where(hit, 1.0 / np.sqrt(1.0 + distance**2), 0.0)
    return sin_top.reshape(MAP_HORIZON_SECTORS, -1).mean(axis=1)


def test_texel_horizons_are_the_walls_exact_horizons():
    """Every covered floor texel away from the chart's edge holds the wall's horizon per sector
    (HORIZON_MAP_RAYS_PER_SECTOR stratified rays in each of MAP_HORIZON_SECTORS: mean error below
    0.05, 95 % below 0.15, none above 0.35; measured 0.019, 0.097, 0.30); the lightmap and its
    objects are found; a lightmap that is not square is refused."""
    scene, floor = _corner_scene()
    assert lightmap_images(scene) == [scene.materials[0].lightmap.image]
    assert lightmap_objects(scene, scene.materials[0].lightmap.image) == scene.objects
    horizons = texel_horizons(scene.objects, (MAP, MAP))
    assert horizons.shape == (MAP, MAP, MAP_HORIZON_SECTORS) and horizons.dtype == np.float32
    # floor texel (row i, column j) centre -> uv1 -> the floor's (s, t) -> position
    rows, cols = np.mgrid[4 : MAP - 4, 4 : MAP // 2 - 4]
    u, v = (cols + 0.5) / MAP, (rows + 0.5) / MAP
    inset = 1.0 / MAP
    s, t = (u - inset) / (0.5 - 2 * inset), (v - inset) / (1.0 - 2 * inset)
    points = np.stack([-1.5 + 3.0 * s, np.zeros_like(s), 1.0 - 2.0 * t], axis=-1).reshape(-1, 3)
    expected = np.array([_wall_horizon_per_sector(p) for p in points])
    found = horizons[rows, cols].reshape(-1, MAP_HORIZON_SECTORS)
    error = np.abs(found - expected)
    assert expected.max() > 0.5  # near the wall, its side is high
    assert error.mean() < 0.05, error.mean()
    assert np.quantile(error, 0.95) < 0.15, np.quantile(error, 0.95)
    assert error.max() < 0.35, error.max()
    with pytest.raises(ValueError, match="square"):
        texel_horizons(scene.objects, (MAP, MAP // 2))


def test_horizon_map_is_cached_by_content(tmp_path, monkeypatch):
    from lobeview.scenes import horizon_maps

    scene, _ = _corner_scene()
    image = scene.materials[0].lightmap.image
    first = lightmap_horizon_map(scene, image, tmp_path)
    assert len(list(tmp_path.glob("horizons-*.npy"))) == 1

    def untraced(*args, **kwargs):
        raise AssertionError("traced again")

    monkeypatch.setattr(horizon_maps, "texel_horizons", untraced)
    np.testing.assert_array_equal(lightmap_horizon_map(scene, image, tmp_path), first)
    next(tmp_path.glob("horizons-*.npy")).write_bytes(b"damaged")
    monkeypatch.undo()
    with pytest.warns(UserWarning):
        again = lightmap_horizon_map(scene, image, tmp_path)  # a damaged file is traced again
    np.testing.assert_array_equal(again, first)


def _bilinear_repeat(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """GL's bilinear read of ``image`` (H, W, C) at ``uv`` (N, 2), repeat wrapping."""
    height, width = image.shape[:2]
    x, y = uv[:, 0] * width - 0.5, uv[:, 1] * height - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]

    def at(i, j):
        return image[np.mod(i, height), np.mod(j, width)]

    return (at(y0, x0) * (1 - fx) * (1 - fy) + at(y0, x0 + 1) * fx * (1 - fy) + at(y0 + 1, x0) * (1 - fx) * fy
            + at(y0 + 1, x0 + 1) * fx * fy)  # fmt: skip


def _unbaked_corner_scene():
    """_corner_scene without its lightmap, its atlas layout as the texture coordinates instead,
    moved by two whole units in u (the map repeats: the chart is found in [0, 1]^2)."""
    scene, floor = _corner_scene()
    obj = scene.objects[0]
    obj.mesh.uvs = (obj.uv1 + [2.0, 0.0]).astype(np.float32)
    obj.uv1 = None
    scene.materials[0].lightmap = None
    return scene, floor


@pytest.mark.parametrize("coordinates", ["lightmap", "texture"])
@pytest.mark.parametrize("method", ["lobe-7", "prefiltered"])
def test_shaders_read_the_horizons_at_the_lightmap_coordinate(method, coordinates):
    """The floor-beside-a-wall test of test_self_visibility with a lightmap: each floor pixel's
    self-occluded / unoccluded ratio is 0.5 + 0.5 vis (the hidden part sees the point itself: F0
    0.5 lit by the lightmap's E = pi), vis from the horizon map read bilinearly at the pixel's
    lightmap coordinate, not from the vertices. Without a lightmap (``texture``): the object's
    own map read at its texture coordinates (lit by the white sky's E = pi)."""
    from lobeview.scenes.self_visibility import split_sum_footprint

    if coordinates == "lightmap":
        scene, _ = _corner_scene()
        image_id = id(scene.materials[0].lightmap.image)

        def inspect(renderer):
            return renderer.shading.horizon_maps[image_id][1]
    else:
        scene, _ = _unbaked_corner_scene()

        def inspect(renderer):
            assert not renderer.shading.horizon_maps and len(renderer.shading.uv0_horizon_maps) == 1
            return renderer.shading.uv0_horizon_maps[0]

    ratio, points, horizons = floor_occlusion_ratios(scene, method, inspect=inspect)
    inset = 1.0 / MAP
    s, t = (points[:, 0] + 1.5) / 3.0, (1.0 - points[:, 2]) / 2.0
    uv1 = np.stack([inset + s * (0.5 - 2 * inset), inset + t * (1.0 - 2 * inset)], axis=-1)
    cones = np.zeros((len(points), 4 + MAP_HORIZON_SECTORS))
    cones[:, :3] = [0.0, 1.0, 0.0]
    cones[:, 4:] = _bilinear_repeat(horizons.astype(np.float64), uv1)
    assert_floor_ratios_follow(ratio, points, cones, split_sum_footprint(0.05**2) if method == "prefiltered" else 0.0)


def test_which_unbaked_objects_get_a_map_over_their_texture_coordinates():
    """An object without a lightmap whose texture coordinates lie in one unit square (after whole
    units) without overlap gets a map; its chart comes back moved into [0, 1]^2. Not: charts
    overlapping (both faces on the same texels), coordinates spanning two units, an object with
    a lightmap (it has the lightmap's map)."""
    from lobeview.scenes.horizon_maps import uv0_chart, uv0_mapped_objects

    baked, _ = _corner_scene()
    assert uv0_mapped_objects(baked) == (0, [])
    scene, _ = _unbaked_corner_scene()
    side, ((index, chart),) = uv0_mapped_objects(scene)
    assert side == 512 and index == 0 and chart.min() >= 0.0 and chart.max() <= 1.0
    np.testing.assert_allclose(chart, scene.objects[0].mesh.uvs - [2.0, 0.0], atol=1e-6)
    overlapping, _ = _unbaked_corner_scene()
    mesh = overlapping.objects[0].mesh
    half = len(mesh.uvs) // 2  # the wall's vertices on the floor's texels
    mesh.uvs[half:] = mesh.uvs[:half]
    assert uv0_mapped_objects(overlapping) == (0, [])
    wide, _ = _unbaked_corner_scene()
    wide.objects[0].mesh.uvs[0] += [1.5, 0.0]
    assert uv0_chart(wide.objects[0]) is None and uv0_mapped_objects(wide) == (0, [])


def test_a_large_atlas_is_traced_coarser_within_the_ray_budget():
    from lobeview.scenes.horizon_maps import HORIZON_MAP_RAYS_PER_SECTOR, horizon_map_size

    scene, _ = _corner_scene()
    rays_per_texel = MAP_HORIZON_SECTORS * HORIZON_MAP_RAYS_PER_SECTOR
    covered = 0.5 * (1 - 2 / MAP) + 0.5 * (1 - 2 / MAP) * (1 - 4 / MAP)  # the two charts' uv area, about
    assert horizon_map_size(scene.objects, 512) == 512  # 0.9 x 512^2 x 64 = 15M rays: within 16M
    assert horizon_map_size(scene.objects, 2048) == 512
    assert horizon_map_size(scene.objects, 512, max_rays=int(covered * 128 * 128 * rays_per_texel) + 1000) == 128
    assert horizon_map_size(scene.objects, 512, max_rays=1) == 1
    image = scene.materials[0].lightmap.image
    assert lightmap_horizon_map(scene, image).shape == (MAP, MAP, MAP_HORIZON_SECTORS)
    with pytest.raises(ValueError, match="square"):
        lightmap_horizon_map(scene, np.zeros((MAP, MAP // 2, 3), np.float32))


def test_the_viewer_takes_its_horizon_maps_from_a_worker(tmp_path, monkeypatch):
    """The viewer's renderer (progressive, with a cache folder) does not trace on its first frame:
    its objects keep the vertices' horizons, the map counted missing; the worker's job (the
    scene's .glb loaded and traced into the cache folder, app/background_bake.py) finds the same
    key; the cube-map build waits after its first bounce until the map is in; installed, the next
    frame draws with it (the records made again), and the finished build equals a renderer that
    traced it before its first frame."""
    from test_self_visibility import FLOOR_CAMERA

    from lobeview.app.background_bake import _trace_horizon_maps
    from lobeview.core.trust import DEFAULT_LIMITS
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    built, _ = _corner_scene()
    path = write_glb(built, tmp_path / "corner.glb", lightmap=built.materials[0].lightmap.image)
    env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=32, name="white")
    ctx = create_headless_context()
    frames = {}
    try:
        for progressive in (True, False):
            scene = load_gltf(path)
            scene.objects[0].planar_reflector = False
            cache = tmp_path / ("worker" if progressive else "traced")
            settings = RenderSettings(cube_face_size=16)
            renderer = SceneRenderer(ctx, scene, env, size=(96, 72), progress=False, cache_dir=cache,
                                     settings=settings, progressive_cubes=progressive)  # fmt: skip
            try:
                if not progressive:
                    assert renderer.shading.missing_horizon_maps == 0 and len(renderer.shading.horizon_maps) == 1
                    frames["traced"] = renderer.render(FLOOR_CAMERA, "lobe-7")
                    continue
                assert renderer.shading.missing_horizon_maps == 1 and not renderer.shading.horizon_maps
                renderer.horizon_maps_traced_elsewhere = True  # as the window sets while its worker runs
                while not renderer.probes.held and renderer.cube_build_status is not None:
                    renderer.continue_cube_build(0.0, FLOOR_CAMERA)  # the first bounce; the next waits
                assert renderer.probes.held and renderer.continue_cube_build(0.0, FLOOR_CAMERA) == 0
                frames["vertices"] = renderer.render(FLOOR_CAMERA, "lobe-7")
                assert _trace_horizon_maps(str(path), str(cache), DEFAULT_LIMITS) == path
                generation = renderer.shading.record_generation
                assert renderer.shading.prepare_horizon_maps(trace=False) == 0  # what the window does
                assert renderer.shading.record_generation > generation
                frames["installed, same cube maps"] = renderer.render(FLOOR_CAMERA, "lobe-7")
                while renderer.cube_build_status is not None:
                    renderer.continue_cube_build(0.0, FLOOR_CAMERA)
                frames["installed"] = renderer.render(FLOOR_CAMERA, "lobe-7")
            finally:
                renderer.release()
    finally:
        ctx.release()
    # what the worker (a fresh process: no cones kept in memory) leaves in a folder of its own
    from collections import OrderedDict

    from lobeview.scenes import self_visibility

    monkeypatch.setattr(self_visibility, "_traced_cones", OrderedDict())
    fresh = tmp_path / "fresh"
    _trace_horizon_maps(str(path), str(fresh), DEFAULT_LIMITS)
    assert len(list(fresh.glob("horizons-*.npy"))) == 1 and len(list(fresh.glob("cones-*.npy"))) == 1
    installed, traced = frames["installed"].radiance, frames["traced"].radiance
    np.testing.assert_allclose(installed, traced, atol=1e-5)
    # the map changes the floor (the check can fail): with the same cube maps, before and after it came
    assert np.abs(frames["installed, same cube maps"].radiance - frames["vertices"].radiance).max() > 0.05


def test_trace_horizon_maps_traces_only_what_the_cache_lacks(tmp_path):
    from lobeview.scenes.horizon_maps import trace_horizon_maps

    scene, _ = _corner_scene()
    image = scene.materials[0].lightmap.image
    assert lightmap_horizon_map(scene, image, tmp_path, trace=False) is None
    assert trace_horizon_maps(scene, tmp_path) == 1
    assert trace_horizon_maps(scene, tmp_path) == 0
    assert lightmap_horizon_map(scene, image, tmp_path, trace=False) is not None


def test_texture_coordinates_too_coarse_for_the_cut_keep_the_vertex_horizons():
    """A texel's width against the near-hit cut (1 % of the extent): the floor alone, its chart a
    quarter of the square over 3 x 2 units (extent 3), has texels of sqrt(6 / (0.25 * side^2)):
    above the cut (0.03) at side 128 (0.038), below at 512 (0.0096); squeezing the wall's chart to
    a sliver makes half the surface coarse, and the object keeps its vertices' horizons."""
    from lobeview.scenes.horizon_maps import coarse_texel_area, uv0_mapped_objects

    scene, floor = _corner_scene()
    floor_object = type(scene.objects[0])("floor", floor, 0)
    quarter = floor.uvs * 0.5
    assert coarse_texel_area(floor_object, quarter, 128) == 1.0
    assert coarse_texel_area(floor_object, quarter, 512) == 0.0
    squeezed, _ = _unbaked_corner_scene()
    uvs = squeezed.objects[0].mesh.uvs
    half = len(uvs) // 2
    uvs[half:] = uvs[half] + (uvs[half:] - uvs[half]) * 0.02  # the wall on a sliver of texels
    assert uv0_mapped_objects(squeezed) == (0, [])


def test_objects_that_hide_nothing_from_themselves_are_not_traced(monkeypatch):
    """A quad, a box and a sphere hide nothing from their own vertices (their cones): the map
    leaves their texels at 0 without tracing them, and no object of theirs gets a map over its
    texture coordinates; the corner (a floor before a wall) is traced."""
    from lobeview.scenes import horizon_maps
    from lobeview.scenes.horizon_maps import hides_from_itself, uv0_mapped_objects
    from lobeview.scenes.meshes import box_mesh, quad, uv_sphere
    from lobeview.scenes.scene import Scene

    scene, _ = _corner_scene()
    corner = scene.objects[0]
    SceneObject = type(corner)
    shapes = [quad((0, 0, 0), (1, 0, 0), (0, 0, 1)), box_mesh((0, 0, 0), (1, 1, 1)), uv_sphere(1.0, 16, 32)]
    convex = [SceneObject(f"shape {i}", mesh, 0) for i, mesh in enumerate(shapes)]
    assert hides_from_itself(corner) and not any(hides_from_itself(obj) for obj in convex)
    assert uv0_mapped_objects(Scene(convex, scene.materials)) == (0, [])
    traced = []
    original = horizon_maps.traced_horizons
    monkeypatch.setattr(horizon_maps, "traced_horizons", lambda *a, **k: traced.append(len(a[1])) or original(*a, **k))
    plane = convex[0]
    plane.uv1 = plane.mesh.uvs.copy()
    assert not texel_horizons([plane], (MAP, MAP)).any() and not traced
    assert texel_horizons([corner], (MAP, MAP)).any() and len(traced) == 1


def test_map_sectors_resolve_a_corridors_open_azimuths():
    """Why a horizon map holds MAP_HORIZON_SECTORS (16) sectors: at the floor of a corridor (walls
    of height 1 at x -+0.2, 2 long) a low direction along it escapes, and so does everything
    within 11.3 degrees of its axis, a crease's narrow open azimuths. With the axis at a 16-sector
    centre, horizons traced in 16 sectors see the direction 10 degrees up along it as open; in 8,
    whose sectors are twice as wide and linear between their centres, the walls on either side
    of the open wedge raise its horizon and hide it (measured: 1.0 and 0.0; by the ray itself, 1)."""
    import trimesh

    from lobeview.scenes.self_visibility import HORIZON_SECTORS, horizon_visibility, traced_horizons

    up = np.array([0.0, 1.0, 0.0])
    tangent, bitangent = horizon_frame(up)
    centre = 0.5 * 2.0 * np.pi / MAP_HORIZON_SECTORS  # the first 16-sector's centre
    axis = np.cos(centre) * tangent + np.sin(centre) * bitangent
    across = np.cross(up, axis)
    boxes = []
    for side in (-1.0, 1.0):  # two thin walls along the axis
        wall = trimesh.creation.box(extents=(0.02, 1.0, 2.0))
        frame = np.eye(4)
        frame[:3, 0], frame[:3, 1], frame[:3, 2] = across, up, axis
        frame[:3, 3] = side * 0.21 * across + 0.5 * up
        wall.apply_transform(frame)
        boxes.append(wall)
    floor = trimesh.creation.box(extents=(3.0, 0.02, 3.0))
    floor.apply_translation([0.0, -0.01, 0.0])
    corridor = trimesh.util.concatenate([*boxes, floor])
    point, extent = np.zeros((1, 3)), float(np.max(corridor.extents))
    low = (np.cos(np.radians(10.0)) * axis + np.sin(np.radians(10.0)) * up)[None]
    assert not corridor.ray.intersects_any(point + 1e-4 * up, low)  # the ray escapes
    shares = {}
    for sectors in (HORIZON_SECTORS, MAP_HORIZON_SECTORS):
        horizons = traced_horizons(corridor, point, up[None], extent, 64, near_hit=1e-3, sectors=sectors)
        cones = np.concatenate([[[0.0, 1.0, 0.0, 0.5]], horizons], axis=1)
        shares[sectors] = float(horizon_visibility(low, cones, up[None], below_hidden=True)[0])
    assert shares[MAP_HORIZON_SECTORS] > 0.9, shares
    assert shares[HORIZON_SECTORS] < 0.5, shares
