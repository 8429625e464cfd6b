"""The blur stack on the GPU (materials/blur_stack.py; built by shaders/blur_stack.comp, read by
shaders/blur_stack.glsl): a 2D texture array of padded faces, layer 6 k + face, RGBA32F
(6 x 34^2 x 10 layers: 1.1 MB a cube)."""

from __future__ import annotations

import moderngl
import numpy as np

from lobeview.materials.blur_stack import STACK_FACE, STACK_LAYERS, STACK_PAD, stack_sigmas

from .mip_chain import GL_RGBA32F, GL_TEXTURE_CUBE_MAP_SEAMLESS, _programs

PADDED = STACK_FACE + 2 * STACK_PAD


def build_blur_stack(ctx: moderngl.Context, cube: moderngl.TextureCube, face_size: int) -> moderngl.TextureArray:
    """The stack of ``cube`` (a radiance cube with its MIP chain, level 0 ``face_size``^2)."""
    stack = ctx.texture_array((PADDED, PADDED, 6 * STACK_LAYERS), 4, dtype="f4")
    stack.filter = (moderngl.LINEAR, moderngl.LINEAR)
    stack.repeat_x = stack.repeat_y = False
    shader = _programs(ctx).compute("blur_stack.comp")
    ctx.enable_direct(GL_TEXTURE_CUBE_MAP_SEAMLESS)
    cube.use(0)
    shader["u_source"] = 0
    shader["u_source_face"] = float(face_size)
    stack.bind_to_image(0, read=False, write=True, format=GL_RGBA32F)
    groups = (PADDED + 7) // 8
    for layer, sigma in enumerate(stack_sigmas()):
        shader["u_layer"] = layer
        shader["u_sigma"] = float(sigma)
        shader.run(groups, groups, 6)
        ctx.memory_barrier()
    return stack


def read_blur_stack(stack: moderngl.TextureArray) -> np.ndarray:
    """(layers, 6, S + 2 P, S + 2 P, 3) float64: the stack as materials/blur_stack.py reads it."""
    data = np.frombuffer(stack.read(alignment=1), dtype=np.float32).reshape(STACK_LAYERS, 6, PADDED, PADDED, 4)
    return data[..., :3].astype(np.float64)
