"""Drives a real ``lobeview view`` window under Xvfb as a person would: python-xlib's XTEST
extension moves the pointer, clicks and presses keys; the viewer's stdout is read line by line.
Used by tests/test_click.py and tests/test_window_input.py."""

from __future__ import annotations

import os
import queue
import re
import subprocess
import sys
import threading
import time

PICKED = re.compile(r"^picked (None|'(.*)') at \(([-\d.]+), ([-\d.]+)\)$")


class XViewer:
    """The viewer process, its stdout as a queue of lines, and an X connection to drive it.
    ``extra``: more ``lobeview view`` options (after the defaults below, so they override them)."""

    def __init__(self, display: str, extra: list[str], size=(900, 500)):
        self.size = tuple(size)
        import tempfile

        from Xlib import display as xdisplay

        # stderr into a file: a pipe nobody reads fills up with progress lines and blocks the viewer.
        self.stderr = tempfile.TemporaryFile("w+")
        size = f"{self.size[0]}x{self.size[1]}"
        command = [sys.executable, "-m", "lobeview", "view", "--view", "overview", "--size", size, "--face-size", "16"]
        self.proc = subprocess.Popen(
            [*command, "--no-vsync", *extra],
            env={**os.environ, "DISPLAY": display},
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            text=True,
        )
        self.lines: queue.Queue = queue.Queue()
        self.printed: list[str] = []  # every stdout line so far (wait_for consumes ``lines``)
        threading.Thread(target=self._pump, daemon=True).start()
        self.x = xdisplay.Display(display)
        self.window = self._find_window(timeout=600)

    def stderr_tail(self) -> str:
        self.stderr.seek(0)
        return self.stderr.read()[-3000:]

    def _pump(self):
        for line in self.proc.stdout:
            self.printed.append(line.rstrip("\n"))
            self.lines.put(line.rstrip("\n"))

    def _find_window(self, timeout: float):
        root = self.x.screen().root
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise AssertionError(f"viewer exited early: {self.stderr_tail()}")
            for child in root.query_tree().children:
                name = child.get_wm_name()
                if isinstance(name, str) and name.startswith("lobeview") and child.get_attributes().map_state:
                    return child
            time.sleep(0.5)
        raise AssertionError("no viewer window appeared")

    def wait_for(self, pattern: str, timeout: float = 300.0) -> re.Match:
        deadline = time.time() + timeout
        while time.time() < deadline:
            try:
                line = self.lines.get(timeout=1.0)
            except queue.Empty:
                if self.proc.poll() is not None:
                    raise AssertionError(f"viewer died: {self.stderr_tail()}") from None
                continue
            match = re.search(pattern, line)
            if match:
                return match
        raise AssertionError(f"no line matching {pattern!r} within {timeout} s")

    def _pointer_to(self, x: int, y: int):
        from Xlib import X
        from Xlib.ext import xtest

        origin = self.window.translate_coords(self.x.screen().root, 0, 0)
        # translate_coords(root -> window) gives minus the window's origin on the screen.
        xtest.fake_input(self.x, X.MotionNotify, x=x - origin.x, y=y - origin.y)
        self.x.sync()

    def press_release(self, x: int, y: int) -> None:
        """The pointer to (x, y), then the left button down for 50 ms, as a quick click."""
        from Xlib import X
        from Xlib.ext import xtest

        self._pointer_to(x, y)
        time.sleep(0.05)
        xtest.fake_input(self.x, X.ButtonPress, 1)
        self.x.sync()
        time.sleep(0.05)
        xtest.fake_input(self.x, X.ButtonRelease, 1)
        self.x.sync()

    def click(self, x: int, y: int) -> str | None:
        """A click the viewer answers with a 'picked' line: the picked object's name (None)."""
        self.press_release(x, y)
        match = PICKED.match(self.wait_for(r"^picked ").string)
        assert match and abs(float(match.group(3)) - x) <= 1 and abs(float(match.group(4)) - y) <= 1, match
        return match.group(2)

    def key(self, keysym_name: str, press: bool = True, release: bool = True):
        from Xlib import XK, X
        from Xlib.ext import xtest

        code = self.x.keysym_to_keycode(XK.string_to_keysym(keysym_name))
        if press:
            xtest.fake_input(self.x, X.KeyPress, code)
        if release:
            xtest.fake_input(self.x, X.KeyRelease, code)
        self.x.sync()

    def close(self) -> int:
        if self.proc.poll() is None:
            self._pointer_to(self.size[0] - 20, self.size[1] - 20)  # keyboard focus follows the pointer
            self.key("Escape")
            try:
                self.proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.x.close()
        return self.proc.wait()
