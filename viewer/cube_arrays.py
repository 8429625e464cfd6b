"""Cube maps in cube-map arrays (issue 42 item 1: GPU-driven drawing of lobe-shaded objects).

Every lobe-shaded object reads its own radiance cube, so one draw call per object binds one
texture. To draw them by multi-draws, the cubes of one face size are copied into the layers of a
``GL_TEXTURE_CUBE_MAP_ARRAY`` (GL 4.0) with ``glCopyImageSubData`` (GL 4.3; every MIP level, on
the GPU) and a shader reads ``textureLod(samplerCubeArray, vec4(dir, layer), lod)``: the same
texels through the same seamless cube filtering, so the frames stay bit-identical (measured on
llvmpipe: every level and layer equal to samplerCube's for random directions and LODs,
tests/test_lobe_batches.py).

moderngl 5.13 wraps neither cube-map arrays nor image copies, and its uniform setter ignores a
``samplerCubeArray`` uniform (unknown type): the array is made through the GL library itself
(ctypes, the GLVND dispatch library that routes every call to the current context, EGL or GLX)
and the shader fixes its unit with ``layout(binding = N)``. Where that library cannot be loaded
or the calls fail, :func:`direct_gl` returns None with the reason and the renderer keeps one draw
per lobe-shaded object (the same frames).

Memory: the arrays hold a copy of each batched cube (the originals stay for the per-object
passes); with a cube-map memory budget (``--cube-budget``) the renderer does not batch lobe-shaded
objects, so the budget keeps its meaning."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field

GL_TEXTURE_CUBE_MAP = 0x8513
GL_TEXTURE_CUBE_MAP_ARRAY = 0x9009
GL_RGBA32F = 0x8814
GL_TEXTURE0 = 0x84C0
GL_TEXTURE_MIN_FILTER = 0x2801
GL_TEXTURE_MAG_FILTER = 0x2800
GL_LINEAR = 0x2601
GL_LINEAR_MIPMAP_LINEAR = 0x2703
GL_NO_ERROR = 0
MAX_PENDING_ERRORS = 32  # glGetError returns one flag per call; a context holds a few at most
RGBA32F_BYTES = 16

# GLVND's libOpenGL exports every core entry point and dispatches to the current context
# (EGL or GLX); libGL.so.1 does the same for GLX-era systems.
GL_LIBRARIES = ("libOpenGL.so.0", "libGL.so.1")

_SIGNATURES = {
    "glGenTextures": (ctypes.c_int, ctypes.POINTER(ctypes.c_uint)),
    "glDeleteTextures": (ctypes.c_int, ctypes.POINTER(ctypes.c_uint)),
    "glBindTexture": (ctypes.c_uint, ctypes.c_uint),
    "glTexStorage3D": (ctypes.c_uint, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_int, ctypes.c_int),
    "glTexParameteri": (ctypes.c_uint, ctypes.c_uint, ctypes.c_int),
    "glCopyImageSubData": (ctypes.c_uint,) * 2 + (ctypes.c_int,) * 4 + (ctypes.c_uint,) * 2 + (ctypes.c_int,) * 7,
    "glActiveTexture": (ctypes.c_uint,),
    "glBindSampler": (ctypes.c_uint, ctypes.c_uint),
    "glGetError": (),
}


class DirectGL:
    """The few GL functions moderngl does not wrap, called on the current context."""

    def __init__(self, library: ctypes.CDLL, name: str):
        self.library_name = name
        for function, argtypes in _SIGNATURES.items():
            entry = getattr(library, function)  # AttributeError: the library lacks it
            entry.argtypes = list(argtypes)
            entry.restype = ctypes.c_uint if function == "glGetError" else None
            setattr(self, function, entry)

    def clear_errors(self) -> list[int]:
        """Read the errors earlier calls left (moderngl, the window library), so :meth:`check`
        reports only this module's; returns them."""
        found = []
        for _ in range(MAX_PENDING_ERRORS):
            error = self.glGetError()
            if error == GL_NO_ERROR:
                break
            found.append(error)
        return found

    def check(self, what: str) -> None:
        """Raise if GL reports an error (after ``what``; call :meth:`clear_errors` before it)."""
        error = self.glGetError()
        if error != GL_NO_ERROR:
            raise RuntimeError(f"{what}: GL error 0x{error:04x}")


_DIRECT: dict = {}


def direct_gl(ctx) -> tuple[DirectGL | None, str]:
    """(the direct GL functions, '') for ``ctx`` (current), or (None, why not): GL older than
    4.3, no GLVND library, or a test array that fails. Checked once per context."""
    key = id(ctx)
    if key in _DIRECT:
        return _DIRECT[key]
    result: tuple[DirectGL | None, str] = (None, "")
    if ctx.version_code < 430:
        result = (None, f"OpenGL {ctx.version_code} has no glCopyImageSubData (4.3)")
    else:
        errors = []
        for name in GL_LIBRARIES:
            try:
                gl = DirectGL(ctypes.CDLL(name), name)
                _probe(gl)
                result = (gl, "")
                break
            except (OSError, AttributeError, RuntimeError) as exc:
                errors.append(f"{name}: {exc}")
        else:
            result = (None, "; ".join(errors))
    _DIRECT[key] = result
    return result


def _probe(gl: DirectGL) -> None:
    """Make, fill and delete a 1-layer 2^2 array: proves the library reaches the current context."""
    gl.clear_errors()
    name = ctypes.c_uint(0)
    gl.glGenTextures(1, ctypes.byref(name))
    if name.value == 0:
        raise RuntimeError("glGenTextures gave no name (no current context through this library)")
    gl.glBindTexture(GL_TEXTURE_CUBE_MAP_ARRAY, name.value)
    gl.glTexStorage3D(GL_TEXTURE_CUBE_MAP_ARRAY, 2, GL_RGBA32F, 2, 2, 6)
    gl.glBindTexture(GL_TEXTURE_CUBE_MAP_ARRAY, 0)
    gl.glDeleteTextures(1, ctypes.byref(name))
    gl.check("a test cube-map array")


def mip_levels(face_size: int) -> int:
    """Levels of a full MIP chain of ``face_size`` texels (what viewer/mip_chain.py upload_cube builds)."""
    return int(face_size).bit_length()


@dataclass
class _ArrayClass:
    """The array of one face size: its GL name, layers, and which texture each layer holds."""

    face_size: int
    levels: int
    capacity: int
    name: int
    layer_of: dict = field(default_factory=dict)  # object index -> layer
    held: list = field(default_factory=list)  # layer -> the cube texture copied into it (or None)


class CubeMapArrays:
    """The residual cubes (viewer/cubemap.py RadianceCube.residual) of the batched objects, one
    cube-map array per face size. :meth:`update` copies a cube into its object's layer when the
    object's texture changed (a progressive build step, a bake bounce, a restored cube); a layer
    keeps a reference to the texture it holds, so identity comparisons cannot alias."""

    def __init__(self, gl: DirectGL):
        self.gl = gl
        self.classes: dict[int, _ArrayClass] = {}
        self.copies = 0  # cubes copied since start-up (tests, reports)

    @property
    def gpu_bytes(self) -> int:
        total = 0
        for c in self.classes.values():
            texels = sum((c.face_size >> level) ** 2 for level in range(c.levels))
            total += texels * 6 * c.capacity * RGBA32F_BYTES
        return total

    def update(self, textures: dict[int, object]) -> dict[int, tuple[int, int]]:
        """``textures``: object index -> its residual cube texture (a moderngl TextureCube).
        Returns object index -> (face size, layer)."""
        by_size: dict[int, list[int]] = {}
        for index, texture in textures.items():
            by_size.setdefault(int(texture.size[0]), []).append(index)
        placed = {}
        for size, indices in by_size.items():
            array = self._array(size, indices)
            for index in indices:
                layer = array.layer_of[index]
                texture = textures[index]
                if array.held[layer] is not texture:
                    self._copy(texture, array, layer)
                    array.held[layer] = texture
                placed[index] = (size, layer)
        for size, array in self.classes.items():  # objects that left a class keep no texture alive
            kept = set(by_size.get(size, ()))
            for index, layer in list(array.layer_of.items()):
                if index not in kept:
                    array.held[layer] = None
                    del array.layer_of[index]
        return placed

    def _array(self, size: int, indices: list[int]) -> _ArrayClass:
        array = self.classes.get(size)
        missing = [i for i in indices if array is None or i not in array.layer_of]
        free = [] if array is None else [k for k in range(array.capacity) if k not in set(array.layer_of.values())]
        if array is None or len(missing) > len(free):
            # (Re)allocate with room for every member; the old layers are copied again from their cubes.
            capacity = max(len(indices), 1)
            if array is not None:
                self._delete(array)
            array = self.classes[size] = self._allocate(size, capacity)
            free = list(range(capacity))
            missing = list(indices)
        for index, layer in zip(missing, free, strict=False):
            array.layer_of[index] = layer
        return array

    def _allocate(self, size: int, capacity: int) -> _ArrayClass:
        gl = self.gl
        gl.clear_errors()
        levels = mip_levels(size)
        name = ctypes.c_uint(0)
        gl.glGenTextures(1, ctypes.byref(name))
        gl.glBindTexture(GL_TEXTURE_CUBE_MAP_ARRAY, name.value)
        gl.glTexStorage3D(GL_TEXTURE_CUBE_MAP_ARRAY, levels, GL_RGBA32F, size, size, 6 * capacity)
        # The filtering upload_cube gives every radiance cube (wrapping does not apply: seamless).
        gl.glTexParameteri(GL_TEXTURE_CUBE_MAP_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR)
        gl.glTexParameteri(GL_TEXTURE_CUBE_MAP_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR)
        gl.glBindTexture(GL_TEXTURE_CUBE_MAP_ARRAY, 0)
        gl.check(f"a cube-map array of {capacity} x 6 faces of {size}^2")
        return _ArrayClass(size, levels, capacity, name.value, {}, [None] * capacity)

    def _copy(self, texture, array: _ArrayClass, layer: int) -> None:
        gl = self.gl
        gl.clear_errors()
        for level in range(array.levels):
            side = max(array.face_size >> level, 1)
            gl.glCopyImageSubData(
                texture.glo, GL_TEXTURE_CUBE_MAP, level, 0, 0, 0,
                array.name, GL_TEXTURE_CUBE_MAP_ARRAY, level, 0, 0, 6 * layer,
                side, side, 6,
            )  # fmt: skip
        gl.check(f"copying a {array.face_size}^2 cube map into layer {layer} of its array")
        self.copies += 1

    def bind(self, face_size: int, unit: int) -> None:
        """Bind the array of ``face_size`` to texture ``unit`` (no sampler object: its own filtering)."""
        gl = self.gl
        gl.glActiveTexture(GL_TEXTURE0 + unit)
        gl.glBindTexture(GL_TEXTURE_CUBE_MAP_ARRAY, self.classes[face_size].name)
        gl.glBindSampler(unit, 0)

    def _delete(self, array: _ArrayClass) -> None:
        name = ctypes.c_uint(array.name)
        self.gl.glDeleteTextures(1, ctypes.byref(name))

    def release(self) -> None:
        for array in self.classes.values():
            self._delete(array)
        self.classes.clear()
