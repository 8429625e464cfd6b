"""The frame's float targets (the G-buffer every shading pass writes) and their framebuffers.

Attachments 0-3: radiance (w < 0 flags NaN/Inf shading), world position (w = 1 on geometry),
shading normal (w = object index + 1, for picking), tangent. With ``plane_state`` (the scene
renderer) two more sets of four float targets hold the averaged-tangent-plane sums of Fig. 4.46b
(points and normals per buffer, locations 4-7): a refinement pass on a reflector writes one set
and reads the set the previous such pass wrote (``begin(averages_planes=True)`` alternates
them); every other pass draws into the plain 4-target framebuffer, so real-time frames neither
clear nor write the state targets.
"""

from __future__ import annotations

import moderngl
import numpy as np

G_BUFFER = ("radiance", "position", "normal", "tangent")  # attachment order (shaders' out locations)


def new_framebuffer(ctx: moderngl.Context, color_attachments, depth_attachment=None):
    """ctx.framebuffer, with the GL error flag left clean: moderngl rebinds the framebuffer that
    was bound before, and when that one has been released since (a cube-face or resize target),
    GL flags GL_INVALID_OPERATION although the new framebuffer is complete (moderngl raises for
    an incomplete one). SceneRenderer.render checks the flag after every frame."""
    fbo = ctx.framebuffer(color_attachments=color_attachments, depth_attachment=depth_attachment)
    _ = ctx.error
    return fbo


def begin_pass(ctx: moderngl.Context, fbo, size) -> None:
    """Bind and clear ``fbo`` for a pass that writes raw values (G-buffer, cube faces, mirror
    buffers), with the GL state such a pass assumes set explicitly. The viewer shares its context
    with the ImGui renderer, which leaves BLEND on: blended writes of float targets whose w is an
    object id or a sample count are garbage (the click crash of issue 17 read 'object 80 of 15').
    """
    ctx.disable(moderngl.BLEND)
    ctx.scissor = None
    fbo.use()
    ctx.viewport = (0, 0, *size)
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)


class FrameTargets:
    def __init__(self, ctx: moderngl.Context, size, plane_state: bool = False):
        self.ctx = ctx
        self.plane_state = plane_state
        self.targets: list = []
        self.resize(size)

    def resize(self, size) -> None:
        self.release()
        self.size = (int(size[0]), int(size[1]))
        self.targets = [self.ctx.texture(self.size, 4, dtype="f4") for _ in G_BUFFER]
        self.depth = self.ctx.depth_renderbuffer(self.size)
        self.plain_fbo = new_framebuffer(self.ctx, self.targets, self.depth)
        self.depth_fbo = new_framebuffer(self.ctx, [], self.depth)  # the depth pre-pass (viewer/occlusion.py)
        self.plane_states = [self.ctx.texture(self.size, 4, dtype="f4") for _ in range(8 if self.plane_state else 0)]
        self.state_fbos = [
            new_framebuffer(self.ctx, [*self.targets, *self.plane_states[4 * k : 4 * k + 4]], self.depth)
            for k in range(2 if self.plane_state else 0)
        ]  # fmt: skip
        self.parity = 0
        self.fbo = self.plain_fbo  # the framebuffer the last pass drew into

    def begin_depth(self, clear: bool) -> None:
        """Bind the depth-only framebuffer (the depth pre-pass); ``clear``: clear its depth first
        (a pre-pass drawn before ``begin``, which then keeps it)."""
        self.depth_fbo.use()
        if clear:
            self.ctx.scissor = None
            self.ctx.viewport = (0, 0, *self.size)
            self.depth_fbo.clear(depth=1.0)

    def begin(self, averages_planes: bool = False, keep_depth: bool = False):
        """Bind and clear the framebuffer of the next pass (see the module doc) and return it.
        ``keep_depth``: clear the colour targets only (the depth pre-pass is drawn already)."""
        if averages_planes:
            if not self.plane_state:
                raise ValueError("these frame targets have no plane-state targets")
            self.parity = 1 - self.parity
            self.fbo = self.state_fbos[self.parity]
        else:
            self.fbo = self.plain_fbo
        self.fbo.depth_mask = not keep_depth  # a framebuffer's clear leaves a masked depth alone
        try:
            begin_pass(self.ctx, self.fbo, self.size)
        finally:
            self.fbo.depth_mask = True
        return self.fbo

    def previous_plane_states(self) -> list:
        """The four state targets the previous averaging pass wrote: point sums (mirror,
        see-through), then normal sums."""
        k = 1 - self.parity
        return self.plane_states[4 * k : 4 * k + 4]

    def read(self, attachment: int) -> np.ndarray:
        """(H, W, 4) float32 of one G-buffer target, row 0 at the top (OpenGL rows start at the
        bottom). Reads the target texture through the plain framebuffer, which every pass's
        framebuffer shares it with."""
        width, height = self.size
        data = self.plain_fbo.read(components=4, attachment=attachment, dtype="f4")
        return np.frombuffer(data, dtype=np.float32).reshape(height, width, 4)[::-1].copy()

    def pick(self, x: int, y: int) -> int | None:
        """Object index under pixel (x, y) (y down) of the last drawn frame, or None."""
        width, height = self.size
        if not (0 <= x < width and 0 <= y < height):
            return None
        data = self.plain_fbo.read(
            viewport=(int(x), int(height - 1 - y), 1, 1), components=4, attachment=G_BUFFER.index("normal"), dtype="f4"
        )
        value = float(np.frombuffer(data, dtype=np.float32)[3])
        return int(round(value)) - 1 if np.isfinite(value) and value >= 0.5 else None

    def release(self) -> None:
        if not self.targets:
            return
        for item in [*self.state_fbos, self.plain_fbo, self.depth_fbo, *self.plane_states, *self.targets, self.depth]:
            item.release()
        self.targets = []
