"""ImGui's input for the walkthrough window, through ImGui's input queue (issue 41).

moderngl-window's renderer (moderngl_window.integrations.imgui_bundle) sets ``io.mouse_down``
and ``io.mouse_pos`` directly. Events arrive once per frame, after the buffer swap, so at a few
frames a second a click's press and release both land before ImGui's next frame reads the
flags: ImGui never sees the button down and a combo does not open. The queue
(``io.add_mouse_*_event``, trickled by ImGui one transition per frame) keeps every press and
release in order, at any frame rate.

The window also needs to know, when an event arrives, whether it belongs to the panel: ImGui's
``want_capture_mouse`` is the previous frame's answer for the previous pointer position, so a
click that moved onto the panel since then went through to the scene. :class:`PanelArea` holds
where the panel was when last drawn and whether a popup was open, and the window asks it.
"""

from __future__ import annotations

from imgui_bundle import imgui
from moderngl_window.integrations.imgui_bundle import ModernglWindowRenderer


class QueuedInputRenderer(ModernglWindowRenderer):
    """moderngl-window's ImGui renderer with mouse input through ImGui's event queue."""

    def _imgui_button(self, button: int) -> int | None:
        mouse = self.wnd.mouse
        return {mouse.left: 0, mouse.right: 1, mouse.middle: 2}.get(button)

    def mouse_position_event(self, x, y, dx, dy):
        self.io.add_mouse_pos_event(*map(float, self._mouse_pos_viewport(x, y)))

    def mouse_drag_event(self, x, y, dx, dy):
        self.io.add_mouse_pos_event(*map(float, self._mouse_pos_viewport(x, y)))

    def mouse_press_event(self, x, y, button):
        self.io.add_mouse_pos_event(*map(float, self._mouse_pos_viewport(x, y)))
        index = self._imgui_button(button)
        if index is not None:
            self.io.add_mouse_button_event(index, True)

    def mouse_release_event(self, x, y, button):
        self.io.add_mouse_pos_event(*map(float, self._mouse_pos_viewport(x, y)))
        index = self._imgui_button(button)
        if index is not None:
            self.io.add_mouse_button_event(index, False)

    def mouse_scroll_event(self, x_offset, y_offset):
        self.io.add_mouse_wheel_event(float(x_offset), float(y_offset))


class PanelArea:
    """Where the panel was when last drawn (x, y, w, h in window coordinates), and whether ImGui
    then held the mouse whatever its position (a popup open, a widget being dragged)."""

    def __init__(self):
        self.rect: tuple[float, float, float, float] | None = None
        self.holds_mouse = False

    def record(self) -> None:
        """Call between the panel window's begin and end, after its last widget."""
        (x, y), (w, h) = imgui.get_window_pos(), imgui.get_window_size()
        self.rect = (float(x), float(y), float(w), float(h))
        any_popup = imgui.PopupFlags_.any_popup_id.value | imgui.PopupFlags_.any_popup_level.value
        self.holds_mouse = imgui.is_popup_open("", any_popup) or imgui.is_any_item_active()

    def contains(self, x: float, y: float) -> bool:
        if self.rect is None:
            return False
        rx, ry, w, h = self.rect
        return rx <= x < rx + w and ry <= y < ry + h

    def captures(self, x: float, y: float) -> bool:
        """Whether a mouse event at (x, y) belongs to the panel: over it when it was last drawn,
        or ImGui holds the mouse whatever its position (an open popup, also one outside the
        panel: a click anywhere closes it; a widget being dragged). Not ``want_capture_mouse``,
        which also answers for where the pointer hovered last frame: a click in the scene just
        after the pointer left the panel would be lost."""
        return self.contains(x, y) or self.holds_mouse
