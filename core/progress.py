"""Progress lines for work a user waits for (issue 18: every step over a second says what it
is): ``[tag] what ...`` before a step that may be long and ``[tag] what: done in X s`` after it.
Lines go to stderr, so a command's own output (tables, paths) stays clean. Ground floor: imports
nothing of lobeview."""

from __future__ import annotations

import contextlib
import os
import sys
import time

#: Steps shorter than this print nothing after they end (the start line is printed regardless
#: only by callers that know a step is long).
SLOW_STEP_SECONDS = 0.5


def quiet() -> bool:
    """``LOBEVIEW_QUIET=1`` silences progress lines (scripts that parse stderr)."""
    return os.environ.get("LOBEVIEW_QUIET", "") not in ("", "0")


_listeners: list = []


@contextlib.contextmanager
def listening(listener):
    """While inside, ``listener(what, fraction)`` hears every :func:`report` (the window's loading
    overlay draws it: issue 41). ``fraction``: 0..1 done, or None when unknown."""
    _listeners.append(listener)
    try:
        yield
    finally:
        _listeners.remove(listener)


def report(what: str, fraction: float | None = None) -> None:
    """Tell the listeners (if any) that a long step is under way, and how far. Call it between
    GPU passes, never inside one: the window's listener draws to the screen."""
    for listener in list(_listeners):
        listener(what, fraction)


@contextlib.contextmanager
def timed_step(tag: str, what: str, announce: bool = False):
    """Time a step; print ``[tag] what: done in X s`` when it took longer than SLOW_STEP_SECONDS,
    and ``[tag] what ...`` first when ``announce`` (the caller knows it is long; the listeners
    hear of it too)."""
    if announce:
        report(what)
    if announce and not quiet():
        print(f"[{tag}] {what} ...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    yield
    seconds = time.perf_counter() - t0
    if (announce or seconds > SLOW_STEP_SECONDS) and not quiet():
        print(f"[{tag}] {what}: done in {seconds:.1f} s", file=sys.stderr, flush=True)
