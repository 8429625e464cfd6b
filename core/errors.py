"""The error of a bad user-given value (a command-line option, a scene name, a size): printed by
the command line as ``lobeview: error: ...`` with exit status 2. In the ground floor, so that the
scene set-up (scenes/setup.py), the benchmarks and the app raise the same one."""

from __future__ import annotations


class OptionError(ValueError):
    """A bad command-line value: printed as ``lobeview: error: ...`` with exit status 2."""


def quoted(value, limit: int = 80) -> str:
    """A value from an input file for a message: repr'd (control characters escaped) and at most
    about ``limit`` characters of it. A string is cut before its repr (a 25 MB string is not
    copied) and says how long it was; anything else is repr'd and cut."""
    if isinstance(value, str):
        shown = repr(value[: limit + 1])
        return shown if len(value) <= limit else shown[:-1] + f"...' ({len(value)} characters)"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


MAX_RENDER_EDGE = 8192  # pixels a side of any image lobeview renders (--size, and times --supersample)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise OptionError(f"--size: expected WxH, got {text!r}") from None
    if not (1 <= w <= MAX_RENDER_EDGE and 1 <= h <= MAX_RENDER_EDGE):
        raise OptionError(f"--size: width and height must be in [1, {MAX_RENDER_EDGE}], got {text!r}")
    return w, h


def check_output_folder(out, option: str = "--out") -> None:
    """An output file's folder must exist: nothing is created where a mistyped path points
    (issue 41: ``--out /nonexistent/dir/a.png`` made /nonexistent/dir). Checked before any work."""
    from pathlib import Path

    out = Path(out)
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist (create it first)"
        raise OptionError(f"cannot write {option} {out}: {folder} {what}")
