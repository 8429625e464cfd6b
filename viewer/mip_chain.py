"""How the MIP chains of incident radiance are made (issue 20, item 1): the cube maps of objects
and environments and the planar mirror buffers that lobe-N, fis-N and the prefilters read
between levels.

"box" is glGenerateMipmap (a 2x2 box per level). "tent" (the default) filters each level from
the one above with the separable tent [1 3 3 1] / 8 (four bilinear reads at +-0.75 source
texels; shaders/mip_tent_cube.comp across the cube's seams, shaders/mip_tent_2d.comp clamped at
a buffer's edges; numpy reference scenes/env_sampling.py tent_downsample_face): a smoother, less
aliased prefilter, so lookups between levels ring less. Measured by bench/mip_chain.py
(results/mip_chain-*.md): with lobe-N's LOD bias at -1 (core/methods.py DEFAULT_LOBE_LOD_BIAS,
chosen for this chain) it beats the box chain at its best bias (-0.5) on 11 of 14 sphere cells.
"""

from __future__ import annotations

import moderngl
import numpy as np

from .shaders import ProgramCache

MIP_FILTERS = ("box", "tent")
DEFAULT_MIP_FILTER = "tent"
GL_RGBA32F = 0x8814
GL_TEXTURE_CUBE_MAP_SEAMLESS = 0x884F


def _programs(ctx: moderngl.Context) -> ProgramCache:
    """The chains' compute shaders, compiled once per context and kept on it: a ProgramCache per
    call made a new GL program for every chain built (every mirror pass of every frame), never
    released."""
    programs = getattr(ctx, "_lobeview_mip_programs", None)
    if programs is None:
        programs = ProgramCache(ctx)
        ctx._lobeview_mip_programs = programs
    return programs


def check_mip_filter(mip_filter: str) -> str:
    if mip_filter not in MIP_FILTERS:
        raise ValueError(f"unknown MIP filter {mip_filter!r}; use one of {MIP_FILTERS}")
    return mip_filter


def tent_mipmaps(ctx: moderngl.Context, cube: moderngl.TextureCube) -> None:
    """Levels 1.. of an RGBA32F ``cube`` (levels allocated) from level 0 with the tent, read
    through seamless cube filtering across face edges."""
    shader = _programs(ctx).compute("mip_tent_cube.comp")
    ctx.enable_direct(GL_TEXTURE_CUBE_MAP_SEAMLESS)
    size = cube.size[0]
    level = 0
    cube.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
    while size > 1:
        size //= 2
        level += 1
        cube.use(0)
        shader["u_source"] = 0
        shader["u_source_lod"] = float(level - 1)
        shader["u_size"] = size
        cube.bind_to_image(0, read=False, write=True, level=level, format=GL_RGBA32F)
        shader.run((size + 7) // 8, (size + 7) // 8, 6)
        ctx.memory_barrier()
    cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)


def tent_mipmaps_2d(ctx: moderngl.Context, texture: moderngl.Texture) -> None:
    """Levels 1.. of an RGBA32F 2D ``texture`` (levels allocated, any size: GL's level sizes
    max(1, size >> level)) from level 0 with the tent, clamped at the edges."""
    shader = _programs(ctx).compute("mip_tent_2d.comp")
    width, height = texture.size
    level = 0
    saved = texture.filter, texture.repeat_x, texture.repeat_y
    texture.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
    texture.repeat_x = texture.repeat_y = False
    while width > 1 or height > 1:
        source = (width, height)
        width, height = max(width // 2, 1), max(height // 2, 1)
        level += 1
        texture.use(0)
        shader["u_source"] = 0
        shader["u_source_lod"] = float(level - 1)
        shader["u_source_size"] = (float(source[0]), float(source[1]))
        shader["u_size"] = (width, height)
        texture.bind_to_image(0, read=False, write=True, level=level, format=GL_RGBA32F)
        shader.run((width + 7) // 8, (height + 7) // 8, 1)
        ctx.memory_barrier()
    texture.filter, texture.repeat_x, texture.repeat_y = saved


def build_mip_chain(
    ctx: moderngl.Context, texture, mip_filter: str = DEFAULT_MIP_FILTER, allocated: bool = False
) -> None:
    """Levels 1.. of a cube or 2D RGBA32F ``texture`` from its level 0 by ``mip_filter``.
    ``allocated``: its levels exist already (a buffer re-filtered every frame), so the tent
    chain does not first make the box chain to allocate them."""
    check_mip_filter(mip_filter)
    if mip_filter == "box" or not allocated:
        texture.build_mipmaps()  # allocates the levels (and is the whole chain for "box")
    if mip_filter == "tent":
        if isinstance(texture, moderngl.TextureCube):
            tent_mipmaps(ctx, texture)
        else:
            tent_mipmaps_2d(ctx, texture)


def read_cube_level(ctx: moderngl.Context, cube: moderngl.TextureCube, level: int) -> np.ndarray:
    """(6, S, S, 4) float32 texels of one MIP level of an RGBA32F cube (moderngl reads level 0
    only), through a compute pass (shaders/cube_level_read.comp)."""
    shader = _programs(ctx).compute("cube_level_read.comp")
    face = max(cube.size[0] >> level, 1)
    out = ctx.buffer(reserve=6 * face * face * 16)
    try:
        cube.bind_to_image(0, read=True, write=False, level=level, format=GL_RGBA32F)
        shader["u_size"] = face
        out.bind_to_storage_buffer(0)
        shader.run((face + 7) // 8, (face + 7) // 8, 6)
        ctx.finish()
        return np.frombuffer(out.read(), dtype=np.float32).reshape(6, face, face, 4).copy()
    finally:
        out.release()


def upload_cube(
    ctx: moderngl.Context, faces: np.ndarray, mipmaps: bool = True, mip_filter: str = DEFAULT_MIP_FILTER
) -> moderngl.TextureCube:
    """An RGBA32F cube map of ``faces`` (6, S, S, 3), with a MIP chain made by ``mip_filter``
    (viewer/mip_chain.py) or none."""
    check_mip_filter(mip_filter)
    size = faces.shape[1]
    cube = ctx.texture_cube((size, size), 4, dtype="f4")
    rgba = np.concatenate([faces, np.ones(faces.shape[:-1] + (1,), np.float32)], axis=-1)
    for face in range(6):
        cube.write(face, np.ascontiguousarray(rgba[face], dtype=np.float32).tobytes())
    ctx.enable_direct(GL_TEXTURE_CUBE_MAP_SEAMLESS)
    if mipmaps:
        build_mip_chain(ctx, cube, mip_filter)
        cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    else:
        cube.filter = (moderngl.LINEAR, moderngl.LINEAR)
    return cube


def downsample_cube_faces(ctx: moderngl.Context, faces: np.ndarray, factor: int, mip_filter: str) -> np.ndarray:
    """(6, S, S, 3) faces -> (6, S/factor, S/factor, 3) as level log2(factor) of their MIP chain
    by ``mip_filter`` (factor a power of two): what a cube rendered finer and then reduced holds
    at level 0 equals that level of the finer cube's own chain."""
    level = int(factor).bit_length() - 1
    if factor < 1 or 1 << level != factor:
        raise ValueError(f"downsample factor must be a power of two, got {factor}")
    if level == 0:
        return np.asarray(faces, dtype=np.float32)
    cube = upload_cube(ctx, faces, mip_filter=mip_filter)
    try:
        return read_cube_level(ctx, cube, level)[..., :3]
    finally:
        cube.release()
