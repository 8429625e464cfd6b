"""The viewer script format (``lobeview view --script FILE``, app/script.py runs it): its actions
and the reader that checks a file before the window opens. Here, below app/, so that the fuzzer
(bench/) reads scripts as the viewer does."""

from __future__ import annotations

from pathlib import Path

from lobeview.core.methods import Method

ACTIONS = (
    "press",
    "release",
    "move",
    "look",
    "select",
    "set",
    "method",
    "screenshot",
    "save_materials",
    "load_materials",
    "undo",
    "click",
    "fit",
    "stats",
    "refine",
    "refinement",
    "path",
    "quit",
)


class ScriptError(ValueError):
    pass


def load_script(path: str | Path) -> list[dict]:
    """Read and check a script: a clear message for a bad step before the window opens."""
    from lobeview.core.jsonio import JSONInputError, read_json_file

    try:
        steps = read_json_file(path, "--script")
    except JSONInputError as exc:
        raise ScriptError(str(exc)) from None
    if not isinstance(steps, list) or not all(isinstance(s, dict) for s in steps):
        raise ScriptError(f"--script {path}: expected a list of steps {{'frame': N, 'action': ...}}")
    for k, step in enumerate(steps):
        if step.get("action") not in ACTIONS:
            raise ScriptError(f"--script {path}: step {k}: action must be one of {', '.join(ACTIONS)}")
        if not isinstance(step.get("frame", 0), int):
            raise ScriptError(f"--script {path}: step {k}: frame must be an integer")
        if step["action"] == "method":
            try:
                Method.parse(str(step.get("value")))
            except ValueError as exc:
                raise ScriptError(f"--script {path}: step {k}: {exc}") from None
    return sorted(steps, key=lambda s: s.get("frame", 0))
