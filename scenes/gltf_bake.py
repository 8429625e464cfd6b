"""Baking a glTF file's lightmaps: ``lobeview bake`` and the viewer's first-use bake (issue 40
item 3: a user's glTF gets occlusion and interreflection without knowing about ``bake``).

The scene is baked into one shared atlas over TEXCOORD_1: the file's own coordinates when every
baked object has them and they do not overlap, else a new xatlas unwrap of all objects. The
output is the input glTF unchanged except for the lightmap (scenes/baked_gltf.py).

First use: a glTF none of whose objects has a lightmap is baked once, with the environment it is
viewed under and ``bake``'s defaults, into the cache folder's ``baked/`` under a name keyed by the
content of everything the bake reads (the scene file, every buffer and image it references, the
environment's bytes or built-in name, the settings): the same file viewed again loads the cached
result at once, an edited file or another environment bakes again. The input's folder is never
written to."""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from lobeview.core.trust import DEFAULT_LIMITS, Limits, read_reference

# More than this fraction of the file's TEXCOORD_1 texels claimed twice: not a shared atlas.
MAX_UV_OVERLAP = 0.05
# Part of the first-use cache key: a change to the baker that changes its output bumps it.
FIRST_USE_BAKE_VERSION = 1


@dataclass(frozen=True)
class BakeSettings:
    """``lobeview bake``'s options (its defaults are the first-use bake's)."""

    resolution: int = 512
    rays: int = 128
    bounces: int = 3
    light_samples: int = 32
    env_samples: int = 32

    def check(self) -> None:
        for name in ("resolution", "rays", "bounces"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name} must be at least 1")
        if self.env_samples < 0 or self.light_samples < 0:
            raise ValueError("--env-samples and --light-samples must not be negative")
        if not 16 <= self.resolution <= 8192:
            raise ValueError("--resolution must be in [16, 8192]")


def has_lightmaps(scene) -> bool:
    """Whether any object of ``scene`` carries a lightmap (then the file is shown as it is)."""
    return any(scene.materials[obj.material].lightmap is not None for obj in scene.objects)


def bake_gltf(
    source: Path,
    environment_spec: str,
    out: Path,
    limits: Limits = DEFAULT_LIMITS,
    settings: BakeSettings = BakeSettings(),
    external_lightmap: bool = False,
    say: Callable[[str], None] = print,
) -> list[Path]:
    """Bake ``source`` under ``environment_spec`` (builtin:NAME or an image file) into the .glb
    ``out``, written atomically (a stopped bake leaves no half file under that name); returns the
    files written."""
    from lobeview.scenes.baked_gltf import write_baked_gltf
    from lobeview.scenes.baker import bake_lightmap, lightmap_uv_overlap
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import unwrap_lightmap_uvs
    from lobeview.scenes.gltf_loader import load_gltf

    settings.check()
    source, out = Path(source), Path(out)
    scene = load_gltf(source, limits)
    missing = [obj.name for obj in scene.objects if obj.uv1 is None]
    overlap = 0.0 if missing else lightmap_uv_overlap(scene, settings.resolution)
    if missing or overlap > MAX_UV_OVERLAP:
        reason = (
            f"{len(missing)} of {len(scene.objects)} objects have no TEXCOORD_1"
            if missing
            else f"the file's TEXCOORD_1 claims {overlap:.0%} of its texels twice (per-object or stacked "
            "lightmap UVs, not one shared atlas)"
        )
        check_texcoord1_free(scene, source)
        say(
            f"{reason}: unwrapping all {len(scene.objects)} objects into one {settings.resolution}^2 atlas "
            "(xatlas); the output's TEXCOORD_1 is the new atlas"
        )
        scene = unwrap_lightmap_uvs(scene, settings.resolution)
    lightmap = bake_lightmap(
        scene,
        load_environment(environment_spec),
        settings.resolution,
        settings.rays,
        settings.bounces,
        light_samples=settings.light_samples,
        env_samples=settings.env_samples,
    )
    # Written in a folder of its own beside ``out``, then moved, the .glb last: a stopped bake
    # leaves no file under the final name that another start would take for finished.
    partial = out.parent / f".{out.name}.partial"
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir()
    try:
        written = write_baked_gltf(source, scene, lightmap, partial / out.name, limits, external_lightmap)
        moved = [out.parent / path.name for path in written]
        for path, target in sorted(zip(written, moved, strict=True), key=lambda pair: pair[0].suffix == ".glb"):
            path.replace(target)
    finally:
        shutil.rmtree(partial, ignore_errors=True)
    return moved


def check_texcoord1_free(scene, source: Path) -> None:
    """A new atlas replaces TEXCOORD_1: refuse when a material's textures read that set."""
    for material in scene.materials:
        for slot_name, slot in material.textures.items():
            if slot.tex_coord == 1:
                raise ValueError(
                    f"{source}: material {material.name!r} reads its {slot_name} texture through TEXCOORD_1, "
                    "which the lightmap atlas would replace; give every object its own non-overlapping "
                    "TEXCOORD_1 lightmap coordinates, or move that texture to TEXCOORD_0"
                )


def referenced_uris(doc: dict) -> list[str]:
    """The files a glTF JSON ``doc`` names (buffers and images; data: URIs excluded), in file order."""
    uris = []
    for key in ("buffers", "images"):
        for item in doc.get(key) or []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                uris.append(uri)
    return uris


def first_use_bake_key(
    source: Path, environment_spec: str, limits: Limits = DEFAULT_LIMITS, settings: BakeSettings = BakeSettings()
) -> str:
    """A digest of everything the bake of ``source`` reads: the file, each file it references
    (through the trust boundary, so a reference outside its folder is refused here as in the
    load), the environment (a built-in by name, a file by its bytes) and the settings."""
    from lobeview.scenes.baked_gltf import parse_source_json

    source = Path(source)
    digest = hashlib.sha256()
    digest.update(f"lobeview first-use bake v{FIRST_USE_BAKE_VERSION} {sorted(asdict(settings).items())}".encode())
    data = read_reference(source.parent, source.name, f"{source}: scene file", limits)
    digest.update(data)
    for uri in referenced_uris(parse_source_json(source, data)):
        digest.update(uri.encode())
        digest.update(hashlib.sha256(read_reference(source.parent, uri, f"{source}: {uri}", limits)).digest())
    if environment_spec.startswith("builtin:"):
        digest.update(environment_spec.encode())
    else:
        digest.update(hashlib.sha256(Path(environment_spec).read_bytes()).digest())
    return digest.hexdigest()[:20]


def first_use_bake_file(
    source: Path,
    environment_spec: str,
    cache: Path,
    limits: Limits = DEFAULT_LIMITS,
    settings: BakeSettings = BakeSettings(),
) -> Path:
    """Where the first-use bake of ``source`` under ``environment_spec`` lives (or will)."""
    key = first_use_bake_key(source, environment_spec, limits, settings)
    return Path(cache) / "baked" / f"{Path(source).stem}-{key}.glb"


def bake_first_use(source: Path, environment_spec: str, out: Path, limits: Limits = DEFAULT_LIMITS) -> Path:
    """The first-use bake itself (the window's worker, or before the first frame): into the cache
    file ``out`` (first_use_bake_file; its folder made), with bake's defaults, silently (the
    unwrap's message is for `lobeview bake`'s user)."""
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    return bake_gltf(Path(source), environment_spec, Path(out), limits, say=lambda _: None)[0]
