"""The cube-map pass (thesis 4.3): per object that needs one, the scene seen from the centre of
its bounding box without itself, with bounces, a disk cache keyed by the scene's content, and
the queue of cube maps made stale by a material edit.

Bounce 1 sees the light-mapped diffuse scene (the thesis' cube maps, where metals are black);
each further bounce re-renders them with the other objects' lobes shaded from the previous
bounce's cube maps, so a chrome sphere shows up in the gold torus and a glass pane is
see-through. The pass draws through the callables the renderer gives it (background, scene),
so it holds no shading code of its own.
"""

from __future__ import annotations

import hashlib
import sys
import threading
import time
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.cache import read_cache_file, write_cache_file
from lobeview.core.cube_layout import face_point_directions
from lobeview.core.methods import Method
from lobeview.core.progress import report

from .camera import outside_frustum_many, perspective
from .cubemap import RadianceCube
from .frame import begin_pass, new_framebuffer
from .mip_chain import DEFAULT_MIP_FILTER, check_mip_filter, downsample_cube_faces

# 11: a hard source is its core's cap (the energy's median spread) and a cone of its glow;
# 10: a source whose cap is not its shape stays whole in the residual (bright_sources.py kept_whole);
# 9: the residual cubes keep each bright source's shape beyond its cap (scenes/bright_sources.py);
# 8: line-pattern footprints held to the lobe's width (materials/patterns.py LINE_MIN_FOOTPRINT_FRACTION);
# 7: the environment read at the face texel's MIP level (shaders/background.frag), not level 0;
# 6: the second bounce shades with bright-source lights and residual cubes (issue 39);
# 5: per-object face sizes (supersampled); 4: glTF textures, alpha modes, culling
CUBE_CACHE_VERSION = 11
CUBE_SUPERSAMPLE = 2
CUBE_BOUNCE_METHOD = Method("lobe", 7)  # how other objects' lobes are shaded inside cube maps


def face_view(face: int, eye) -> np.ndarray:
    """View matrix whose image plane maps (x, y) in NDC to (sc, tc) of the cube face, so the
    framebuffer (row 0 = t = 0) is the face's texel layout (core/cube_layout.py)."""
    zero = np.zeros(1)
    f = face_point_directions(face, zero, zero)[0]
    r = face_point_directions(face, np.ones(1), zero)[0] * np.sqrt(2) - f  # d/dsc
    u = face_point_directions(face, zero, np.ones(1))[0] * np.sqrt(2) - f  # d/dtc
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = r, u, -f
    view[:3, 3] = -view[:3, :3] @ np.asarray(eye, dtype=np.float64)
    return view


def scene_content_key(
    scene,
    environment_key: str,
    face_size: int,
    bounces: int,
    sizes: dict | None = None,
    mip_filter: str = DEFAULT_MIP_FILTER,
    bright_sources: bool = False,
) -> str:
    """What the cube maps depend on: geometry, lightmap coordinates, materials, emission,
    lightmaps and base-colour textures, the environment, face size (and each object's, ``sizes``),
    bounces, the MIP chains (second-bounce lookups read them; sized faces are reduced by them) and
    whether bright sources are separated (the second bounce then shades them as lights)."""
    h = hashlib.sha256()
    h.update(f"v{CUBE_CACHE_VERSION} face{face_size} b{bounces} env{environment_key} mip-{mip_filter}".encode())
    if bright_sources:
        h.update(b" bright-sources")
    if sizes:
        h.update(f"ss{CUBE_SUPERSAMPLE}".encode() + repr(sorted(sizes.items())).encode())
    for obj in scene.objects:
        h.update(obj.mesh.positions.tobytes())
        h.update(obj.mesh.indices.tobytes())
        if obj.uv1 is not None:
            h.update(obj.uv1.tobytes())
    for mat in scene.materials:
        h.update(repr(sorted(mat.desc.items())).encode())
        h.update(np.asarray(mat.emission, np.float64).tobytes())
        if mat.lightmap is not None:
            h.update(hashlib.sha256(mat.lightmap.image.tobytes()).digest())
        for name in sorted(mat.textures):
            h.update(name.encode() + mat.textures[name].key())
        h.update(repr((mat.base_alpha, mat.alpha_mode, mat.alpha_cutoff, mat.normal_scale,
                       mat.occlusion_strength, mat.double_sided)).encode())  # fmt: skip
    return h.hexdigest()[:20]


def light_report(named_lights: list, shown: int = 8) -> str:
    """One line saying which cube maps hold bright sources taken out as cap lights (issue 39:
    what each object sees; an object whose cube has none integrates no light), from (object
    name, its cube's CapLights) pairs: per object the lights' count and angular radii, the
    objects with the most lights first, ``shown`` of them."""
    seen = sorted(((name, lights) for name, lights in named_lights if lights), key=lambda item: -len(item[1]))
    if not seen:
        return f"[lights] no bright source in any of the {len(named_lights)} cube maps: no cap lights"
    parts = []
    for name, lights in seen[:shown]:
        radii = sorted(float(np.degrees(np.arccos(np.clip(light.cos_radius, -1.0, 1.0)))) for light in lights)
        span = f"{radii[0]:.1f}" if len(radii) == 1 else f"{radii[0]:.1f}-{radii[-1]:.1f}"
        parts.append(f"{name} {len(lights)} ({span} deg)")
    more = f", and {len(seen) - shown} more" if len(seen) > shown else ""
    return (f"[lights] bright sources as cap lights in {len(seen)} of {len(named_lights)} cube maps: "
            + ", ".join(parts) + more)  # fmt: skip


class CubeBake:
    """Renders cube maps through ``drawer`` (viewer/object_drawer.py ObjectDrawer: its
    environment, background and draw loop); ``objects`` are its GPU objects (``.cube``,
    ``.name``, and ``.probe_centre`` / ``.probe_exclude``: where an object's cube map is rendered
    from and without whom, scenes/probe_groups.py)."""

    def __init__(
        self,
        ctx: moderngl.Context,
        face_size: int,
        bounces: int,
        scene_extent: float,
        drawer,
        progress: bool = True,
        cache_dir: Path | None = None,
        mip_filter: str = DEFAULT_MIP_FILTER,
        bright_sources: bool = False,
    ):
        self.ctx = ctx
        self.mip_filter = check_mip_filter(mip_filter)  # of every cube map made here
        self.bright_sources = bool(bright_sources)  # separate each cube's bright sources (viewer/cubemap.py)
        # Where the cube maps are cached; every cube made here carries it, for the prefiltered
        # maps cached beside it. The scene key is set by build().
        self.cache_dir = Path(cache_dir) if cache_dir else None
        self.key = ""
        self.face_size = int(face_size)
        self.bounces = max(1, int(bounces))
        self.scene_extent = float(scene_extent)
        self.environment = drawer.environment
        self.drawer = drawer
        self.progress = progress
        self.stale: list[int] = []  # cube maps that show an outdated appearance of another object
        self.cache_writer: threading.Thread | None = None  # a progressive build's cache file being written
        # Sized cube maps to re-render at the full face size (refinement in view: SceneRenderer
        # request_full_faces), after the stale ones.
        self.upgrades: list[int] = []

    def render_faces(self, eye, exclude=None, specular: bool = False, size: int | None = None) -> np.ndarray:
        """Six faces of the light-mapped scene seen from ``eye`` (float32, (6, S, S, 3), S =
        ``size`` or the full face size) without the object(s) ``exclude`` (an index or a set);
        with ``specular``, objects that have cube maps are shaded with their lobes too."""
        size = int(size or self.face_size)
        factor = max(1, min(CUBE_SUPERSAMPLE, self.face_size // size))
        if factor > 1:  # render finer and reduce: level 0 then equals level k of the full face's chain
            fine = self._render_faces(eye, exclude, specular, size * factor)
            return downsample_cube_faces(self.ctx, fine, factor, self.mip_filter)
        return self._render_faces(eye, exclude, specular, size)

    def _render_faces(self, eye, exclude, specular: bool, size: int) -> np.ndarray:
        color = self.ctx.texture((size, size), 4, dtype="f4")
        extra = [self.ctx.texture((size, size), 4, dtype="f4") for _ in range(3)]
        depth = self.ctx.depth_renderbuffer((size, size))
        fbo = new_framebuffer(self.ctx, [color, *extra], depth)
        proj = perspective(90.0, 1.0, 1e-3 * self.scene_extent, 4.0 * self.scene_extent)
        faces = np.empty((6, size, size, 3), dtype=np.float32)
        viewport = self.ctx.viewport
        try:
            for face in range(6):
                view_proj = proj @ face_view(face, eye)
                begin_pass(self.ctx, fbo, (size, size))
                self.drawer.draw_background(self.environment, view_proj)
                self.drawer.draw(view_proj, eye, CUBE_BOUNCE_METHOD, specular, exclude, pass_kind="cube map")
                self.ctx.finish()
                data = np.frombuffer(fbo.read(components=4, attachment=0, dtype="f4"), np.float32)
                faces[face] = data.reshape(size, size, 4)[..., :3]  # row 0 = t = 0, no flip
        finally:
            fbo.release()
            depth.release()
            color.release()
            for t in extra:
                t.release()
            self.ctx.viewport = viewport
        return faces

    def _cache_file(self, index: int | None = None) -> Path | None:
        """The start-up cache file (``index`` None) or one object's on-demand file."""
        if self.cache_dir is None:
            return None
        return self.cache_dir / (f"cubes-{self.key}.npz" if index is None else f"cubes-{self.key}-object{index}.npz")

    def _install(self, obj, faces: np.ndarray) -> None:
        """Make ``faces`` the object's cube map (releasing the one it had)."""
        if obj.cube is not None:
            obj.cube.release()
        obj.cube = RadianceCube(
            self.ctx,
            np.asarray(faces, dtype=np.float32),
            mip_filter=self.mip_filter,
            bright_sources=self.bright_sources,
        )
        obj.cube.cache_dir = self.cache_dir

    @staticmethod
    def _read_faces(path: Path, member: str, size: int) -> np.ndarray | None:
        """One cube map of a cache file (None: the file does not hold it)."""
        shape = (6, size, size, 3)
        with np.load(path, allow_pickle=False) as data:
            if member not in data.files:
                return None
            faces = data[member]
        if faces.shape != shape or not np.all(np.isfinite(faces)):
            raise ValueError(f"cube map is not a finite array of shape {shape}")
        return faces

    def _sizes(self, wanted: list[int], sizes: dict | None) -> dict[int, int]:
        return {i: int((sizes or {}).get(i, self.face_size)) for i in wanted}

    def build_from_cache(self, objects: list, wanted: list[int], key: str, sizes: dict | None = None) -> bool:
        """Install the cube maps of ``wanted`` from the disk cache when it holds them all, at
        their sizes; False when it does not (nothing installed). Sets the cache ``key``."""
        self.key = key
        if not wanted:
            return True
        sizes = self._sizes(wanted, sizes)

        def read(path: Path) -> dict | None:
            with np.load(path, allow_pickle=False) as data:
                if not {f"cube_{i}" for i in wanted} <= set(data.files):
                    return None  # another selection of objects (the scene analysis changed): render
                cached = {i: data[f"cube_{i}"] for i in wanted}
            for i, c in cached.items():
                shape = (6, sizes[i], sizes[i], 3)
                if c.shape != shape:
                    return None  # another face size for this object (its material changed): render
                if not np.all(np.isfinite(c)):
                    raise ValueError("cube maps are not finite")
            return cached

        cached = read_cache_file(self._cache_file(), read, "cube maps")
        if cached is None:
            return False
        for i in wanted:
            self._install(objects[i], cached[i])
        return True

    def build(self, objects: list, wanted: list[int], key: str, sizes: dict | None = None) -> None:
        """Cube maps of the objects ``wanted``, from the disk cache when it has them all; ``sizes``
        gives an object's face size (default: the full one, scenes/analysis.py chooses); ``key``
        names the cache files (scene_content_key)."""
        if not self.build_from_cache(objects, wanted, key, sizes):
            for _ in self.build_steps(objects, wanted, sizes):
                pass
        elif self.progress and self.bright_sources:
            self._report_lights(objects, wanted)

    def _report_lights(self, objects: list, wanted: list[int]) -> None:
        print(light_report([(objects[i].name, objects[i].cube.lights) for i in wanted]), file=sys.stderr, flush=True)

    def build_steps(
        self,
        objects: list,
        wanted: list[int],
        sizes: dict | None = None,
        cache: bool = True,
        nearest=None,
        announce: bool = True,
        background_write: bool = False,
        bounces: int | None = None,
    ):
        """Render the cube maps of ``wanted`` with every bounce, one object's six faces per step
        (a generator: it yields (steps done, steps in all) after each), so a window can spread the
        work over frames. The result is :meth:`build`'s exactly: the first bounce's cube maps are
        installed as each is made (that bounce draws no cube map, so the order does not matter
        and ``nearest(remaining)`` may choose the next object, the camera's nearest first); a
        later bounce's are installed together at its end, as every object of it reads the
        previous bounce's. ``cache``: write the cache file (under the key set before) at the end;
        ``announce``: tell the progress listeners (a window's loading overlay) of each step;
        ``background_write``: write the cache file in a thread (``cache_writer``); ``bounces``:
        fewer than the bake's (the progressive start's previews: the first bounce only)."""
        if not wanted:
            return
        sizes = self._sizes(wanted, sizes)
        faces = {}
        count = self.bounces if bounces is None else min(bounces, self.bounces)
        cache_file = self._cache_file() if cache and count == self.bounces else None  # only the finished maps
        total = self.steps_for(len(wanted), cache_file is not None, count)
        done = 0
        for bounce in range(count):
            t0 = time.perf_counter()
            remaining = list(wanted)
            while remaining:
                i = nearest(remaining) if nearest is not None and bounce == 0 else remaining[0]
                remaining.remove(i)
                obj = objects[i]
                if announce:
                    report(
                        f"cube maps, bounce {bounce + 1} of {count}: {obj.name} "
                        f"({len(wanted) - len(remaining)} of {len(wanted)})",
                        done / total,
                    )
                faces[i] = self.render_faces(obj.probe_centre, obj.probe_exclude, specular=bounce > 0, size=sizes[i])
                if bounce == 0:
                    self._install(obj, faces[i])
                done += 1
                yield done, total
            if bounce > 0:  # every face of this bounce is made: installing them now is exact, one per step
                for i in wanted:
                    self._install(objects[i], faces[i])
                    done += 1
                    yield done, total
            if self.progress and announce:
                counts = np.unique(list(sizes.values()), return_counts=True)
                shapes = ", ".join(f"{c} of {s}^2" for s, c in zip(*counts, strict=True))
                print(
                    f"[cube] bounce {bounce + 1}: {len(wanted)} cube maps x 6 faces ({shapes})"
                    f" in {time.perf_counter() - t0:.2f} s",
                    file=sys.stderr,
                    flush=True,
                )
        if self.progress and announce and self.bright_sources:
            self._report_lights(objects, wanted)
        if cache_file is not None:
            # float32, not float16: a sun seen through a window exceeds half precision's 65504.
            arrays = {f"cube_{i}": f.astype(np.float32) for i, f in faces.items()}

            def write() -> None:  # a read-only cache folder: rendered again next time
                write_cache_file(cache_file, lambda handle: np.savez_compressed(handle, **arrays))

            if background_write:
                # Compressing the apartment's cube maps takes ~8 s: a window frame must not wait
                # for it (zlib releases the GIL). Not a daemon: an exiting process finishes it,
                # and the file appears whole or not at all (write_cache_file renames it).
                self.cache_writer = threading.Thread(target=write, name="cube-map cache", daemon=False)
                self.cache_writer.start()
            else:
                write()
            yield total, total

    def steps_for(self, cube_maps: int, cached: bool, bounces: int | None = None) -> int:
        """The steps build_steps takes for ``cube_maps``: one render per object and bounce, one
        install per object and later bounce, and the cache file's write (``bounces``: build_steps'
        own, default the bake's)."""
        bounces = self.bounces if bounces is None else bounces
        return (2 * bounces - 1) * cube_maps + int(cached)

    def build_one(self, objects: list, index: int, size: int, cached: bool = True) -> str:
        """The cube map of one object on demand (a reflector whose mirror pass does not shade it
        this frame, or a restored one): one bounce over the other objects' finished cube maps,
        which is what the last bounce of :meth:`build` gives it; cached in its own file beside the
        others (``cached`` False: neither read nor written, the scene changed since start-up).
        Returns where it came from: 'disk cache' or 'rendered'."""
        cache_file = self._cache_file(index) if cached else None
        faces = read_cache_file(cache_file, lambda path: self._read_faces(path, "cube", size), "cube map")
        if faces is not None:
            self._install(objects[index], faces)
            return "disk cache"
        t0 = time.perf_counter()
        obj = objects[index]
        faces = self.render_faces(obj.probe_centre, obj.probe_exclude, specular=self.bounces > 1, size=size)
        if self.progress:
            print(
                f"[cube] {objects[index].name}: cube map of {size}^2 x 6 on demand in {time.perf_counter() - t0:.2f} s",
                file=sys.stderr,
                flush=True,
            )
        if cache_file is not None:
            write_cache_file(cache_file, lambda handle: np.savez_compressed(handle, cube=faces.astype(np.float32)))
        self._install(objects[index], faces)
        return "rendered"

    def restore(self, objects: list, index: int, size: int, edited: bool) -> str:
        """Bring back an evicted cube map (:class:`CubeResidency`): from the start-up cache file
        when the scene is as it was then (not ``edited``), else through :meth:`build_one` (its own
        file, or rendered again: one bounce over the other cube maps, as a refreshed cube).
        Returns where it came from."""
        main = None if edited else self._cache_file()
        faces = read_cache_file(main, lambda path: self._read_faces(path, f"cube_{index}", size), "cube maps")
        if faces is not None:
            self._install(objects[index], faces)
            return "disk cache"
        return self.build_one(objects, index, size, cached=not edited)

    def refresh_one(self, objects: list) -> str | None:
        """Re-render the next stale cube map (at its size), else the next queued upgrade to the
        full face size; returns its object's name (None: nothing was waiting)."""
        while self.stale or self.upgrades:
            upgrade = not self.stale
            obj = objects[(self.upgrades if upgrade else self.stale).pop(0)]
            if obj.cube is None or (upgrade and obj.cube.face_size >= self.face_size):
                continue
            size = self.face_size if upgrade else obj.cube.face_size
            self._install(
                obj, self.render_faces(obj.probe_centre, obj.probe_exclude, specular=self.bounces > 1, size=size)
            )
            return obj.name
        return None


class CubeResidency:
    """A GPU memory budget for the cube maps (issue 18; ``SceneRenderer(cube_budget_mb=...)``,
    ``--cube-budget``): after each frame, while the cube maps (with their MIP chains and any
    prefiltered maps) exceed the budget, the least recently drawn are released, never one drawn
    in that frame; before a pass draws an evicted object it is restored (viewer/cube_bake.py
    CubeBake.restore). ``None``: no budget."""

    def __init__(self, budget_bytes: int | None):
        self.budget = None if budget_bytes is None else int(budget_bytes)
        self.frame = 0
        self.last_used: dict[int, int] = {}
        self.evicted: set[int] = set()
        self.evictions = 0
        self.restores: dict[str, int] = {}  # where restored cube maps came from -> count
        self.restore_seconds = 0.0

    def touch(self, index: int) -> None:
        self.last_used[index] = self.frame

    def evict(self, objects: list) -> list[int]:
        """End of a frame: release least recently drawn cube maps until under budget."""
        self.frame += 1
        if self.budget is None:
            return []
        resident = [obj for obj in objects if obj.cube is not None]
        total = sum(cube_gpu_bytes(obj.cube) for obj in resident)
        released = []
        drawn_now = self.frame - 1
        for obj in sorted(resident, key=lambda o: self.last_used.get(o.index, -1)):
            if total <= self.budget or self.last_used.get(obj.index, -1) >= drawn_now:
                break
            total -= cube_gpu_bytes(obj.cube)
            obj.cube.release()
            obj.cube = None
            self.evicted.add(obj.index)
            released.append(obj.index)
        self.evictions += len(released)
        return released

    def wanted(self, corners: np.ndarray, view_projection: np.ndarray, exclude=None) -> list[int]:
        """Evicted objects whose bounding box reaches the frustum of ``view_projection``, but
        ``exclude`` (an index or a collection of them)."""
        if not self.evicted:
            return []
        excluded = set(exclude) if isinstance(exclude, frozenset | set | tuple | list) else {exclude}
        indices = sorted(i for i in self.evicted if i not in excluded)
        inside = ~outside_frustum_many(corners[indices], view_projection)
        return [i for i, keep in zip(indices, inside, strict=True) if keep]

    def report(self, objects: list) -> str:
        resident = [obj.cube for obj in objects if obj.cube is not None]
        memory = sum(cube_gpu_bytes(cube) for cube in resident) / 2**20
        budget = "no budget" if self.budget is None else f"budget {self.budget / 2**20:.0f} MB"
        if self.budget is not None and memory * 2**20 > self.budget:
            budget += ", exceeded by what the last frame drew"
        restored = ", ".join(f"{n} from {where}" for where, n in sorted(self.restores.items())) or "none"
        return (
            f"cube maps: {len(resident)} resident, {memory:.0f} MB ({budget}); {self.evictions} evicted, "
            f"restored {restored} ({self.restore_seconds:.1f} s)"
        )


def cube_gpu_bytes(cube: RadianceCube) -> int:
    """GPU bytes of a radiance cube with its MIP chain (twice where bright sources were separated:
    the residual is a second cube; three times once prefiltered maps were made from the cube without
    sources), and the prefiltered maps built from it."""
    from .prefiltered import cube_bytes

    maps = cube.built_prefiltered_maps
    chains = cube.texture_chains
    return chains * cube_bytes(cube.face_size, int(np.log2(cube.face_size)) + 1) + (maps.total_memory() if maps else 0)
