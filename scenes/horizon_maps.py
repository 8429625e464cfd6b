"""Specular self-occlusion per lightmap texel (issue 40): the horizons of scenes/self_visibility.py
traced at every covered texel of a baked object's lightmap instead of at its vertices.

Why: against Cycles' light passes (bench/cycles_passes.py, cycles_trace.py) 90-97 % of the
remaining error on the glTF models lies on the pixels whose glossy lobe the object hides from
itself, where vertex horizons, interpolated over triangles centimetres wide, cannot hold a 3 mm
ledge or a crevice: traced at each pixel's own point with a near-hit cut of 1 % of the extent, the
mirror direction's visible share falls from 0.56 to 0.03 on the WaterBottle (Cycles 0.13) and
0.40 to 0.19 on DamagedHelmet (0.12), and stays 0.98-1.00 on the open pixels (a smaller cut at
the vertices hid the open surface: a vertex at a crease sees the faces around it). A baked
object's lightmap texels are 0.3-0.7 % of its extent, fine enough for that.

The map of a lightmap (the charts of the objects that read it, in one atlas, each object's texels
traced against its own mesh only: what other objects hide is in its cube map) holds per texel the sines
of the MAP_HORIZON_SECTORS horizons (self_visibility.traced_horizons, the vertices' frame
horizon_frame about the texel's interpolated normal), dilated into the gutter so that bilinear
reads at chart edges stay on the chart's values; uncovered texels hold 0 (nothing hidden).
shaders/scene.frag reads it at the lightmap coordinate in place of the vertices' horizons.

An object without a lightmap (a user's glTF shot as it is) gets a map of its own over its texture
coordinates (TEXCOORD_0) where they can hold one: inside one unit square (shifted by whole units:
the map repeats), without overlap (mirrored or stacked charts would give two surfaces one
texel: DamagedHelmet's halves share theirs) and with texels small against the near-hit cut on
nearly all of its surface (an artist's atlas gives parts that no texture shows a few texels:
Suzanne's UV0 texels are 1.8 % of its extent at the median, 71 % of its surface has texels above
the 1 % cut, and its map made it 13.2 % off Cycles against 10.7 % with vertex horizons; the
WaterBottle's 0.34 %, 0.8 % of its surface above: 14.1 -> 5.4 %), at most UV0_HORIZON_MAP_SIZE a
side, all of a scene's such maps together within HORIZON_MAP_MAX_RAYS.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from lobeview.core.cache import read_cache_file, write_cache_file

from .baker import dilate, rasterize_uv, uv_overlap, uv_triangle_areas
from .self_visibility import MAP_HORIZON_SECTORS, NO_OCCLUSION, SEED, object_visibility_cones, traced_horizons

HORIZON_MAP_NEAR_HIT = 0.01  # the near-hit cut per texel, times the object's extent (measured above)
HORIZON_MAP_RAYS_PER_SECTOR = 8  # MAP_HORIZON_SECTORS of them: 128 rays a texel
HORIZON_MAP_DILATION = 2  # texels grown into the gutter around each chart
# 2: objects that hide nothing from their vertices are not traced; 3: MAP_HORIZON_SECTORS (16, was 8)
HORIZON_MAP_VERSION = "horizon-map-3"
# Rays a lightmap's map may trace (as MAX_SELF_VISIBILITY_RAYS_TOTAL bounds the cones'): a larger
# atlas is traced at half its resolution, again, until its covered texels fit (32M rays; 128 a
# texel: 6-8.5 s for the WaterBottle's, Suzanne's and DamagedHelmet's 512^2 atlases, 32-58 %
# covered, on 2 cores; the bilinear read at the lightmap coordinate is the same).
HORIZON_MAP_MAX_RAYS = 32_000_000
# An object without a lightmap: its map over TEXCOORD_0 at most this many texels a side (the
# WaterBottle's texels then 0.4 % of its extent, as its 512^2 lightmap's), its charts overlapping
# on at most UV0_MAX_OVERLAP of their texels (what texel-centre sampling along chart edges gives).
UV0_HORIZON_MAP_SIZE = 512
UV0_MAX_OVERLAP = 0.02
UV0_MAX_COARSE_AREA = 0.05  # the share of the surface whose texels may exceed the near-hit cut


def uv1_lightmap(scene, obj):
    """The lightmap image ``obj`` reads through its own lightmap coordinates (TEXCOORD_1), or None:
    what has a horizon map."""
    lightmap = scene.materials[obj.material].lightmap
    return lightmap.image if lightmap is not None and lightmap.tex_coord == 1 and obj.uv1 is not None else None


def lightmap_images(scene) -> list:
    """The distinct lightmap images (by identity) that objects read through their own lightmap
    coordinates: one horizon map each, in that lightmap's layout (one texture, as the lightmap,
    so the multi-draws that group objects by their textures stay as they are)."""
    images = {}
    for obj in scene.objects:
        image = uv1_lightmap(scene, obj)
        if image is not None:
            images.setdefault(id(image), image)
    return list(images.values())


def lightmap_objects(scene, image) -> list:
    """The objects that read ``image`` (a lightmap) through their own lightmap coordinates."""
    return [obj for obj in scene.objects if uv1_lightmap(scene, obj) is image]


def texel_horizons(
    objects, size: tuple[int, int], near_hit: float = HORIZON_MAP_NEAR_HIT, uvs: list | None = None
) -> np.ndarray:
    """(H, W, MAP_HORIZON_SECTORS) float32: the horizon sines at the texel centres of a (W, H) = ``size``
    lightmap covered by ``objects``' lightmap coordinates (scenes/scene.py SceneObject.uv1; or
    ``uvs``, one (V, 2) array per object), each traced against its own object, dilated
    HORIZON_MAP_DILATION texels; 0 elsewhere."""
    import trimesh

    width, height = size
    if width != height:
        raise ValueError(f"horizon maps follow square lightmaps, got {width}x{height}")
    horizons = np.zeros((height, width, MAP_HORIZON_SECTORS), dtype=np.float64)
    covered = np.zeros((height, width), dtype=bool)
    for obj, uv in zip(objects, uvs if uvs is not None else [obj.uv1 for obj in objects], strict=True):
        if not hides_from_itself(obj):
            continue  # its texels keep 0: nothing hidden, as its vertices say
        faces = np.asarray(obj.mesh.indices, dtype=np.int64).reshape(-1, 3)
        positions = np.asarray(obj.mesh.positions, dtype=np.float64)
        normals = np.asarray(obj.mesh.normals, dtype=np.float64)
        samples = rasterize_uv(np.asarray(uv, dtype=np.float64), positions, normals, faces, width)
        if not len(samples.pixel) or len(faces) < 2:
            continue
        mesh = trimesh.Trimesh(positions, faces, process=False)
        extent = float(np.max(positions.max(axis=0) - positions.min(axis=0)))
        traced = traced_horizons(
            mesh, samples.position, samples.normal, extent, HORIZON_MAP_RAYS_PER_SECTOR, SEED, near_hit,
            sectors=MAP_HORIZON_SECTORS,
        )  # fmt: skip
        rows, cols = samples.pixel[:, 0], samples.pixel[:, 1]
        horizons[rows, cols] = traced
        covered[rows, cols] = True
    if covered.any():
        horizons = dilate(horizons, covered, steps=HORIZON_MAP_DILATION)
    return horizons.astype(np.float32)


def hides_from_itself(obj) -> bool:
    """Whether any vertex of the object sees its own surface (its visibility cones, scenes/
    self_visibility.py, traced once and kept on it): a plane, a box or any convex object hides
    nothing from itself, and its horizon map would be all zeros at the cost of every texel's rays
    (the apartment's walls, floors and boxes)."""
    cones = object_visibility_cones(obj)
    return bool(np.any(cones[:, 3] > NO_OCCLUSION))


def _key(objects, size, uvs: list) -> str:
    digest = hashlib.sha256(
        repr(
            (
                HORIZON_MAP_VERSION,
                HORIZON_MAP_NEAR_HIT,
                HORIZON_MAP_RAYS_PER_SECTOR,
                HORIZON_MAP_DILATION,
                MAP_HORIZON_SECTORS,
                SEED,
                tuple(size),
            )
        ).encode()  # fmt: skip
    )
    for obj, uv in zip(objects, uvs, strict=True):
        for array in (obj.mesh.positions, obj.mesh.normals, obj.mesh.indices, uv):
            data = np.ascontiguousarray(array)
            digest.update(f"{data.dtype.str}{data.shape}".encode())
            digest.update(data.tobytes())
    return digest.hexdigest()[:20]


def horizon_map_size(objects, lightmap_size: int, max_rays: int = HORIZON_MAP_MAX_RAYS, uvs=None) -> int:
    """The side of the map traced for a ``lightmap_size`` atlas: halved until the texels the
    objects' lightmap coordinates (or ``uvs``) cover (their charts' area) times the rays a texel
    traces fit ``max_rays``; at least 1."""
    uvs = uvs if uvs is not None else [obj.uv1 for obj in objects]
    area = sum(
        float(uv_triangle_areas(np.asarray(uv, dtype=np.float64), np.asarray(obj.mesh.indices).reshape(-1, 3)).sum())
        for obj, uv in zip(objects, uvs, strict=True)
    )
    rays_per_texel = MAP_HORIZON_SECTORS * HORIZON_MAP_RAYS_PER_SECTOR
    size = int(lightmap_size)
    while size > 1 and min(area, 1.0) * size * size * rays_per_texel > max_rays:
        size //= 2
    return size


def lightmap_horizon_map(scene, image, cache_folder: Path | None = None, trace: bool = True) -> np.ndarray | None:
    """The horizon map of the lightmap ``image`` (texel_horizons over the objects that read it, at
    horizon_map_size), from ``cache_folder`` when traced before; traced (and cached) otherwise,
    or None with ``trace`` False (the viewer's first frame: app/background_bake.py traces it)."""
    objects = lightmap_objects(scene, image)
    if image.shape[0] != image.shape[1]:
        raise ValueError(f"horizon maps follow square lightmaps, got {image.shape[1]}x{image.shape[0]}")
    uvs = [obj.uv1 for obj in objects]
    return _horizon_map(objects, uvs, horizon_map_size(objects, int(image.shape[0])), cache_folder, trace)


def uv0_chart(obj) -> np.ndarray | None:
    """The object's texture coordinates (TEXCOORD_0) moved by whole units into [0, 1]^2 (the map
    repeats as the shader reads it), or None where they span more than one unit or are not finite."""
    uvs = getattr(obj.mesh, "uvs", None)
    if uvs is None or len(uvs) != len(obj.mesh.positions) or not len(uvs):
        return None
    uv = np.asarray(uvs, dtype=np.float64)
    if not np.all(np.isfinite(uv)):
        return None
    uv = uv - np.floor(uv.min(axis=0))
    return uv if float(uv.max()) <= 1.0 else None


def coarse_texel_area(obj, uv: np.ndarray, side: int, near_hit: float = HORIZON_MAP_NEAR_HIT) -> float:
    """The share of the object's surface whose texels, on a ``side`` map over ``uv``, are wider
    than ``near_hit`` times its extent (a triangle's texel width: the square root of its area over
    the texels its chart covers)."""
    faces = np.asarray(obj.mesh.indices, dtype=np.int64).reshape(-1, 3)
    positions = np.asarray(obj.mesh.positions, dtype=np.float64)
    extent = float(np.max(positions.max(axis=0) - positions.min(axis=0)))
    edges = positions[faces[:, 1:]] - positions[faces[:, :1]]
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    if extent <= 0.0 or area.sum() <= 0.0:
        return 1.0
    texels = uv_triangle_areas(uv, faces) * side * side
    width = np.sqrt(area / np.maximum(texels, 1e-30))
    return float(area[width > near_hit * extent].sum() / area.sum())


def uv0_mapped_objects(scene) -> tuple[int, list[tuple[int, np.ndarray]]]:
    """(side, [(object index, uv0_chart)]): the objects that read no lightmap through their own
    lightmap coordinates but whose texture coordinates can hold a horizon map (uv0_chart; charts
    overlapping on at most UV0_MAX_OVERLAP at UV0_HORIZON_MAP_SIZE), and the one side of their
    maps (halved from UV0_HORIZON_MAP_SIZE until all fit HORIZON_MAP_MAX_RAYS), keeping those
    whose texels at that side exceed the near-hit cut on at most UV0_MAX_COARSE_AREA of their
    surface."""
    candidates = []
    for index, obj in enumerate(scene.objects):
        if uv1_lightmap(scene, obj) is not None or len(obj.mesh.indices) < 6 or not hides_from_itself(obj):
            continue
        uv = uv0_chart(obj)
        if uv is None:
            continue
        # the cheap tests first (the overlap's rasterising takes a second per object in Python):
        # charts whose area exceeds the square's overlap (a box's faces each over [0, 1]^2), and
        # texels too coarse even at the largest side
        area = float(uv_triangle_areas(uv, np.asarray(obj.mesh.indices, dtype=np.int64).reshape(-1, 3)).sum())
        if area > 1.0 + UV0_MAX_OVERLAP or coarse_texel_area(obj, uv, UV0_HORIZON_MAP_SIZE) > UV0_MAX_COARSE_AREA:
            continue
        if uv_overlap([(uv, obj.mesh)], UV0_HORIZON_MAP_SIZE) <= UV0_MAX_OVERLAP:
            candidates.append((index, uv))
    if not candidates:
        return 0, []
    objects = [scene.objects[index] for index, _ in candidates]
    side = horizon_map_size(objects, UV0_HORIZON_MAP_SIZE, uvs=[uv for _, uv in candidates])
    kept = [(i, uv) for i, uv in candidates if coarse_texel_area(scene.objects[i], uv, side) <= UV0_MAX_COARSE_AREA]
    return side, kept


def uv0_horizon_map(
    scene, index: int, uv: np.ndarray, side: int, cache_folder: Path | None = None, trace: bool = True
) -> np.ndarray | None:
    """The horizon map of object ``index`` over its texture coordinates ``uv`` at ``side``
    (uv0_mapped_objects), cached as lightmap_horizon_map's."""
    return _horizon_map([scene.objects[index]], [uv], side, cache_folder, trace)


def _horizon_map(objects, uvs: list, side: int, cache_folder: Path | None, trace: bool) -> np.ndarray | None:
    size = (side, side)
    path = None if cache_folder is None else Path(cache_folder) / f"horizons-{_key(objects, size, uvs)}.npy"

    def read(file: Path) -> np.ndarray:
        found = np.load(file, allow_pickle=False)
        if found.shape != (size[1], size[0], MAP_HORIZON_SECTORS) or found.dtype != np.float32:
            raise ValueError(f"horizon map of shape {found.shape} ({found.dtype})")
        if not np.all(np.isfinite(found)):
            raise ValueError("horizon map with non-finite values")
        return found

    found = read_cache_file(path, read, "horizon map")
    if found is not None or not trace:
        return found
    horizons = texel_horizons(objects, size, uvs=uvs)
    if path is not None:
        write_cache_file(path, lambda handle: np.save(handle, horizons, allow_pickle=False))
    return horizons


def square_lightmap_images(scene) -> list:
    """lightmap_images that can have a horizon map (square ones; the viewer warns about the rest)."""
    return [image for image in lightmap_images(scene) if image.shape[0] == image.shape[1]]


def trace_horizon_maps(scene, cache_folder: Path) -> int:
    """Trace into ``cache_folder`` the horizon maps of ``scene`` it lacks (a worker process's
    job: app/background_bake.py), its lightmaps' and its unbaked objects', with progress; the
    number traced."""
    from lobeview.core.progress import report

    images = square_lightmap_images(scene)
    missing = [image for image in images if lightmap_horizon_map(scene, image, cache_folder, trace=False) is None]
    side, mapped = uv0_mapped_objects(scene)
    unmapped = [(i, uv) for i, uv in mapped if uv0_horizon_map(scene, i, uv, side, cache_folder, trace=False) is None]
    total = len(missing) + len(unmapped)
    for done, image in enumerate(missing):
        report(f"self-occlusion horizons per texel: lightmap {done + 1} of {len(missing)}", done / total)
        lightmap_horizon_map(scene, image, cache_folder)
    for done, (index, uv) in enumerate(unmapped):
        report(f"self-occlusion horizons per texel: {scene.objects[index].name}", (len(missing) + done) / total)
        uv0_horizon_map(scene, index, uv, side, cache_folder)
    return total
