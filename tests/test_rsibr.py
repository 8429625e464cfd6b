"""Reflection-space IBR (seed 004): the numpy reference (materials/rsibr.py) against independent
computations, the GPU bake against numpy Monte Carlo, and rendered pixels against the numpy twin
of the shader's warp and blend (shaders/rsibr.glsl)."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials import rsibr as rs


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("subdivisions,views,faces", [(0, 12, 20), (1, 42, 80)])
def test_geodesic_sphere_is_a_closed_outward_triangulation(subdivisions, views, faces):
    vertices, tris = rs.geodesic_sphere(subdivisions)
    assert vertices.shape == (views, 3) and tris.shape == (faces, 3)
    assert np.allclose(np.linalg.norm(vertices, axis=1), 1.0)
    a, b, c = (vertices[tris[:, i]] for i in range(3))
    assert np.all(np.sum(np.cross(b - a, c - a) * a, axis=1) > 0)  # counter-clockwise from outside
    edges = {}
    for tri in tris:
        for i in range(3):
            edge = tuple(sorted((tri[i], tri[(i + 1) % 3])))
            edges[edge] = edges.get(edge, 0) + 1
    assert set(edges.values()) == {2}  # every edge shared by exactly two faces: closed
    assert np.isclose(rs.triangle_area(a, b, c).sum(), 4 * np.pi)


def _dihedral_area(a, b, c):
    """The seed's spherical excess (section 3.4): the sum of the three angles between the planes
    through the vertex pairs (normalised cross products) minus pi."""

    def ncross(x, y):
        z = np.cross(x, y)
        return z / np.linalg.norm(z, axis=-1, keepdims=True)

    def angle(p, q):
        return np.arccos(np.clip(np.sum(p * q, axis=-1), -1, 1))

    alpha = angle(ncross(a, b), ncross(a, c))
    beta = angle(ncross(b, c), ncross(b, a))
    gamma = angle(ncross(c, a), ncross(c, b))
    return alpha + beta + gamma - np.pi


def test_triangle_area_matches_the_seeds_dihedral_form_and_monte_carlo():
    rng = np.random.default_rng(1)
    a, b, c = _unit(rng, 200), _unit(rng, 200), _unit(rng, 200)
    assert np.allclose(rs.triangle_area(a, b, c), _dihedral_area(a, b, c), atol=1e-9)
    # One face of the icosahedron holds 1/20 of the sphere; a small triangle by counting points.
    vertices, faces = rs.geodesic_sphere(0)
    points = _unit(rng, 400_000)
    inside = rs.containing_face(points, vertices, faces) == 0
    assert abs(inside.mean() - 1 / 20) < 4 * np.sqrt(0.05 * 0.95 / len(points))


def test_view_weights_are_barycentric_and_continuous():
    vertices, faces = rs.geodesic_sphere(0)
    rng = np.random.default_rng(2)
    v = _unit(rng, 5000)
    views, weights = rs.view_weights(v, vertices, faces)
    assert np.all(weights >= -1e-12) and np.allclose(weights.sum(axis=1), 1.0)
    # The chosen face holds v: v is on the inner side of its three edge planes.
    a, b, c = (vertices[views[:, i]] for i in range(3))
    for p, q in ((a, b), (b, c), (c, a)):
        assert np.all(np.sum(np.cross(p, q) * v, axis=1) >= -1e-12)
    # At a view the map is that view's alone.
    views_at, weights_at = rs.view_weights(vertices, vertices, faces)
    for k in range(len(vertices)):
        assert np.isclose(weights_at[k][views_at[k] == k].sum(), 1.0)

    def dense(u):
        idx, w = rs.view_weights(u, vertices, faces)
        out = np.zeros((len(u), len(vertices)))
        np.put_along_axis(out, idx, w, axis=1)
        return out

    # Continuous across the faces' edges: a step of 1e-6 moves every weight by O(1e-6).
    step = _unit(rng, 5000) * 1e-6
    moved = v + step - np.sum(step * v, axis=1, keepdims=True) * v
    assert np.max(np.abs(dense(moved) - dense(v))) < 1e-4


def test_mirror_warp_reflects_each_view_into_the_same_direction():
    rng = np.random.default_rng(3)
    r, view = _unit(rng, 1000), _unit(rng, 1000)
    keep = np.sum(r * view, axis=1) > -0.99
    n = rs.warped_normal(r[keep], view[keep])
    assert np.allclose(rs.reflect(view[keep], n), r[keep], atol=1e-9)
    # n_j . v_j = |v_j + r| / 2, the confidence's argument; 0 weight at the singular texel.
    assert np.allclose(np.sum(n * view[keep], axis=1), 0.5 * np.linalg.norm(view[keep] + r[keep], axis=1))
    assert rs.confidence(-view[0], view[0]) == 0.0
    assert rs.confidence(view[0], view[0]) == 1.0


def test_slice_frames_and_tangent_angles_invert_each_other():
    rng = np.random.default_rng(4)
    n = _unit(rng, 2000)
    n[:3] = [[0, 0, 1], [0, 0, -1], [0, 1e-5, 1]]  # the poles of the field and next to one
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    angle = rng.random(2000) * np.pi
    frame = rs.slice_frame(n, angle)
    assert np.allclose(np.einsum("nij,nik->njk", frame, frame), np.eye(3), atol=1e-9)  # orthonormal
    assert np.allclose(np.linalg.det(frame), 1.0)
    assert np.allclose(rs.tangent_angle(frame[..., 0], n), angle, atol=1e-9)
    # pi-periodic: the opposite tangent has the same angle
    assert np.allclose(rs.tangent_angle(-frame[..., 0], n), angle, atol=1e-9)


def test_blend_reproduces_view_independent_maps_and_each_view_at_its_own_direction():
    vertices, faces = rs.geodesic_sphere(0)
    rows, slices = 32, 2
    rng = np.random.default_rng(5)
    # Maps that all hold the same smooth function of r: any convex blend returns it (bilinear).
    u = (np.arange(2 * rows) + 0.5) / (2 * rows)
    v = (np.arange(rows) + 0.5) / rows
    from lobeview.scenes.envmap import equirect_direction

    uu, vv = np.meshgrid(u, v)
    dirs = equirect_direction(uu, vv)
    tile = np.concatenate([dirs * 0.5 + 0.5, np.ones(dirs.shape[:2] + (1,))], axis=-1)
    atlas = np.stack([tile] * (len(vertices) * slices))
    view = _unit(rng, 300)
    frame = rs.slice_frame(_unit(rng, 300), rng.random(300) * np.pi)
    frame[..., 2] *= np.sign(np.sum(frame[..., 2] * view, axis=1))[:, None]
    got = rs.rsibr_radiance(atlas, slices, vertices, faces, view, frame)
    r = rs.reflect(view, frame[..., 2])
    assert np.allclose(got, rs.tile_lookup(atlas, 0, r))
    # Maps holding their own view's index and slice: at a view direction only that map counts,
    # and the slice weights follow the tangent's angle.
    marks = np.zeros_like(atlas)
    for t in range(len(vertices) * slices):
        marks[t] = t
    n = _unit(rng, len(vertices))
    n *= np.sign(np.sum(n * vertices, axis=1))[:, None]
    angle = np.full(len(vertices), np.pi / 4)  # halfway between slices 0 and 1 of K = 2
    got = rs.rsibr_radiance(marks, slices, vertices, faces, vertices, rs.slice_frame(n, angle, vertices))
    assert np.allclose(got[:, 0], np.arange(len(vertices)) * slices + 0.5)


def test_map_rows_follow_the_narrowest_lobe():
    from lobeview.materials.microfacet import MicrofacetDistribution

    wide = MicrofacetDistribution("ggx", 0.5, 0.5)
    narrow = MicrofacetDistribution("ggx", 0.02, 0.02)
    assert rs.map_rows([wide], False) < rs.map_rows([wide, narrow], False) == rs.RSIBR_MAX_ROWS
    assert rs.map_rows([narrow], True) == rs.RSIBR_MAX_ROWS_ANISOTROPIC
    # two texels across the median angle: pi / rows <= angle / 2
    angle = rs.median_reflection_angle(wide)
    assert np.pi / rs.map_rows([wide], False) <= angle / 2


# -- on the GPU ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def gl():
    from test_render_vs_numpy import SIZE, smooth_sky

    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.gl_probes import CubeLookup
    from lobeview.viewer.preview import PreviewRenderer

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(smooth_sky, height=256, name="smooth-sky")
    renderer = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=SIZE, face_size=128)
    yield renderer, CubeLookup(ctx, renderer.programs)
    renderer.release()
    ctx.release()


def _maps(renderer, bsdf):
    """(maps (tiles, rows, 2 rows, 4), layout) of the maps the last render bound for ``bsdf``."""
    from lobeview.viewer.material_gpu import pack_material
    from lobeview.viewer.rsibr import rsibr_cache_key, rsibr_layout

    material = pack_material(bsdf)
    layout = rsibr_layout(material)
    texture = renderer.cubes.prefiltered_maps()._rsibr[rsibr_cache_key(material, layout)]
    width, height, layers = layout.shape
    return np.frombuffer(texture.read(), dtype=np.float32).reshape(layers, height, width, 4).astype(np.float64), layout


def _specular_only(bsdf):
    from lobeview.materials.bsdf import BSDF

    return BSDF([c for c in bsdf.components if getattr(c, "distribution", None) is not None], "specular")


@pytest.mark.parametrize("preset", ["gold-ggx", "brushed-steel-beckmann"])
def test_baked_maps_match_numpy_monte_carlo(gl, preset):
    """Texels of the GPU maps (fis-256 at n_j = normalize(v_j + r), tangent at the slice angle)
    against numpy importance sampling of the same lobes from the same cube."""
    from test_render_vs_numpy import CAMERA, _numpy_reference

    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.scenes.envmap import equirect_direction

    renderer, lookup = gl
    bsdf = build_bsdf(load_material(preset))
    renderer.render(CAMERA, bsdf, "prefiltered-rsibr", background=False)
    atlas, layout = _maps(renderer, bsdf)
    assert np.all(atlas[..., 3] == 1.0)  # no texel integrated to NaN/Inf
    vertices, _ = rs.geodesic_sphere(layout.subdivisions)
    rng = np.random.default_rng(6)
    specular = _specular_only(bsdf)
    errors = []
    for _ in range(12):
        j, k = rng.integers(len(vertices)), rng.integers(layout.slices)
        x, y = rng.integers(2 * layout.rows), rng.integers(layout.rows)
        r = equirect_direction((x + 0.5) / (2 * layout.rows), (y + 0.5) / layout.rows)
        if r @ vertices[j] < -0.5:  # the maps' grazing texels weigh little (confidence); skip them
            continue
        frame = rs.slice_frame(rs.warped_normal(r, vertices[j]), k * np.pi / layout.slices, vertices[j])
        wo = frame.T @ vertices[j]
        expected = _numpy_reference(specular, frame, wo / np.linalg.norm(wo), lookup, renderer.cubes.radiance)
        got = atlas[j * layout.slices + k, y, x, :3]
        errors.append(np.abs(got - expected).sum() / max(expected.sum(), 1e-3))
    assert len(errors) >= 6 and np.median(errors) < 0.03 and max(errors) < 0.1, errors


@pytest.mark.parametrize("preset", ["gold-ggx", "brushed-steel-beckmann"])
def test_render_matches_the_numpy_warp_and_blend(gl, preset):
    """Rendered pixels (no diffuse term in these presets) against rsibr_radiance on the same maps
    with the pixel's G-buffer frame and view: the face search, spherical barycentric weights,
    confidence, slice mix, elevation correction and bilinear tile reads of shaders/rsibr.glsl."""
    from test_render_vs_numpy import CAMERA, _frame, _pixels

    from lobeview.materials.spec import build_bsdf, load_material

    renderer, _ = gl
    bsdf = build_bsdf(load_material(preset))
    result = renderer.render(CAMERA, bsdf, "prefiltered-rsibr", background=False)
    assert not result.invalid.any()
    atlas, layout = _maps(renderer, bsdf)
    vertices, faces = rs.geodesic_sphere(layout.subdivisions)
    albedo = rs.albedo_table(_specular_only(bsdf).components)
    for y, x in _pixels(result, count=24, seed=7):
        frame, wo = _frame(result, y, x)
        expected = rs.rsibr_radiance(atlas[..., :3], layout.slices, vertices, faces, frame @ wo, frame, albedo)
        got = result.radiance[y, x]
        assert np.allclose(got, expected, rtol=0.02, atol=2e-3), (y, x, got, expected)


def test_plan_bakes_reflection_lobes_and_leaves_the_rest_to_auto():
    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.viewer.material_gpu import pack_material
    from lobeview.viewer.prefilter_modes import prefilter_plan

    frosted = pack_material(build_bsdf(load_material("frosted-glass")))
    assert prefilter_plan(frosted, "rsibr") == ["rsibr", "lobe"]  # the thin transmission lobe: a lobe map
    gold = pack_material(build_bsdf(load_material("gold-ggx")))
    assert prefilter_plan(gold, "rsibr") == ["rsibr"]
    assert prefilter_plan(gold, "rsibr", per_pixel_lobes=True) == prefilter_plan(gold, "auto") == ["splitsum"]


def test_scene_materials_with_lobe_textures_are_not_baked():
    """shaders/scene.frag changes a glTF material's lobes per pixel from every texture but
    occlusion, emission and (without a clearcoat) the normal map: such materials keep the
    automatic lookup under prefiltered-rsibr."""
    from lobeview.scenes.scene import SceneMaterial
    from lobeview.viewer.scene_shading import per_pixel_lobes

    gltf = {"model": "gltf", "base_color": [0.8, 0.8, 0.8], "metallic": 1.0, "roughness": 0.3}
    slot = object()  # only the slot names matter here
    assert not per_pixel_lobes(SceneMaterial("plain", gltf))
    assert not per_pixel_lobes(SceneMaterial("mapped", gltf, textures={"normal": slot, "occlusion": slot}))
    assert per_pixel_lobes(SceneMaterial("rough", gltf, textures={"metallic_roughness": slot}))
    assert per_pixel_lobes(SceneMaterial("base", gltf, textures={"base_color": slot}))
    coated = {**gltf, "clearcoat": 0.5}
    assert per_pixel_lobes(SceneMaterial("coated", coated, textures={"normal": slot}))
    thesis = {"model": "thesis", "kd": 0.5, "lobes": [{"ks": 0.5, "mx": 0.1, "my": 0.1, "r0": 0.5, "alpha": 0.3}]}
    assert not per_pixel_lobes(SceneMaterial("thesis", thesis, textures={"base_color": slot}))


def test_maps_are_cached_on_disk_and_rebuilt_when_damaged(gl, tmp_path):
    """Baked maps come back bit-identical from the cache folder; a damaged file is warned about,
    baked again (to the same texels) and rewritten whole."""
    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.viewer.material_gpu import pack_material
    from lobeview.viewer.prefiltered import PrefilteredMaps
    from lobeview.viewer.rsibr import bake_rsibr, rsibr_cache_key, rsibr_layout

    renderer, _ = gl
    material = pack_material(build_bsdf(load_material("gold-ggx")))
    layout = rsibr_layout(material)
    key = rsibr_cache_key(material, layout)
    bakes = []

    def bake(texture):
        bakes.append(1)
        bake_rsibr(renderer.shading, renderer.cubes, material, layout, texture)

    def maps():
        return PrefilteredMaps(renderer.ctx, renderer.cubes, renderer.programs, tmp_path)

    first = maps()
    texels = first.rsibr_map(layout, key, bake).read()
    (path,) = tmp_path.glob("prefiltered-rsibr-*.npz")
    second = maps()
    assert second.rsibr_map(layout, key, bake).read() == texels and len(bakes) == 1
    path.write_bytes(path.read_bytes()[:300])  # truncated
    third = maps()
    with pytest.warns(UserWarning, match="unusable cached"):
        again = third.rsibr_map(layout, key, bake).read()
    assert len(bakes) == 2 and again == texels
    with np.load(path) as data:
        assert data["texels"].shape == (layout.tiles, layout.rows, 2 * layout.rows, 4)
    for m in (first, second, third):
        m.release()


def test_each_maps_tangent_field_is_smooth_over_its_warped_normals():
    """map_tangent(n, v_j): unit, perpendicular to n, canonical_tangent(v_j) at v_j, and turning no
    faster than the normal over the hemisphere n . v_j >= 0 (the global field turns by up to 180
    degrees between normals 2e-3 apart around its poles at +-Z); slice_frame and tangent_angle
    with a view invert each other."""
    vertices, _ = rs.geodesic_sphere(1)
    rng = np.random.default_rng(12)
    for view in vertices:
        n = _unit(rng, 400)
        n *= np.sign(n @ view)[:, None]
        step = 1e-3 * _unit(rng, 400)
        moved = (n + step) / np.linalg.norm(n + step, axis=1, keepdims=True)
        t, t_moved = rs.map_tangent(n, view), rs.map_tangent(moved, view)
        assert np.allclose(np.linalg.norm(t, axis=1), 1.0) and np.allclose(np.sum(t * n, axis=1), 0.0, atol=1e-9)
        assert np.max(np.linalg.norm(t - t_moved, axis=1)) < 3.0 * np.max(np.linalg.norm(n - moved, axis=1))
        assert np.allclose(rs.map_tangent(view, view), rs.canonical_tangent(view))
        angle = rng.random(400) * np.pi
        frame = rs.slice_frame(n, angle, view)
        assert np.allclose(rs.tangent_angle(frame[..., 0], n, view), angle, atol=1e-9)
    pole = np.array([[1e-3, 0.0, 1.0], [-1e-3, 0.0, 1.0]])
    assert abs(rs.canonical_tangent(pole)[0] @ rs.canonical_tangent(pole)[1]) > 0.99  # the global field flips


def test_transported_tangent_is_the_smallest_rotation():
    """transported_tangent against scipy's rotation taking n to m about n x m: unit, perpendicular
    to m, and the identity for m = n."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(9)
    n = _unit(rng, 200)
    m = n + 0.6 * _unit(rng, 200)
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    t = np.cross(n, _unit(rng, 200))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    axis = np.cross(n, m)
    angle = np.arctan2(np.linalg.norm(axis, axis=1), np.sum(n * m, axis=1))
    rotation = Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1, keepdims=True) * angle[:, None])
    assert np.allclose(rs.transported_tangent(t, n, m), rotation.apply(t), atol=1e-9)
    assert np.allclose(rs.transported_tangent(t, n, n), t, atol=1e-12)


@pytest.mark.parametrize("rotation", [0.0, np.pi / 2], ids=["along-x", "along-y"])
def test_anisotropic_maps_on_a_plane_facing_an_axis(rotation):
    """A strongly anisotropic metal quad (glTF anisotropy 1, roughness 0.4) facing +Z under
    builtin:studio, seen near its normal: prefiltered-rsibr within 25 % of the reference. With the
    tangent field's poles at +-Z and each pixel's slice measured at its own normal rather than at
    each map's, the slices named other tangents there: 1.9-2.9x (along x) and 1.4-1.9x (along y)."""
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.meshes import quad
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    desc = {"model": "gltf", "base_color": [0.9, 0.9, 0.9], "metallic": 1.0, "roughness": 0.4, "anisotropy": 1.0,
            "anisotropy_rotation": rotation}  # fmt: skip
    bsdf = build_bsdf(validate(desc))
    ctx = create_headless_context()
    renderer = PreviewRenderer(ctx, load_environment("builtin:studio"), quad((0, 0, 0), (1, 0, 0), (0, 1, 0)),
                               size=(40, 40), face_size=64)  # fmt: skip
    try:
        for position in ((0.6, 1.2, 1.6), (0.5, 0.5, 2.0)):
            camera = Camera(position=position, target=(0.5, 0.5, 0.0), fov_y=40.0)
            reference = renderer.render(camera, bsdf, "reference", spp=256, background=False)
            truth = float(reference.radiance[reference.mask].mean())
            result = renderer.render(camera, bsdf, "prefiltered-rsibr", background=False)
            got = float(result.radiance[result.mask].mean())
            assert abs(got / truth - 1.0) < 0.25, (position, got, truth)
    finally:
        renderer.release()
        ctx.release()
