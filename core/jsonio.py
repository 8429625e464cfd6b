"""One reader for every JSON file lobeview takes (issue 43 item 1): material files, material edits,
camera paths, viewer scripts and inline material JSON. Untrusted input: the file must be a
regular file (a FIFO would block the open forever, a device would stream without end), no
larger than a limit checked before anything is read, nested no deeper than MAX_JSON_DEPTH, with
numbers no longer than MAX_NUMBER_CHARS characters and finite (a 400-digit integer overflowed
later as a float; NaN and Infinity are not JSON). Errors name the file, the place and the limit,
and quote at most QUOTE_CHARS characters of what they refuse. The regular-file and size check is
core/trust.py's check_regular_file, as for CSV, MERL and HDR inputs."""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

from lobeview.core.errors import quoted

MAX_JSON_BYTES = 32 * 2**20  # larger than any material, path or script lobeview writes by far
MAX_JSON_DEPTH = 64
MAX_NUMBER_CHARS = 40  # digits, sign, point and exponent of one number
QUOTE_CHARS = 80  # core.errors.quoted's default


class JSONInputError(ValueError):
    """A JSON input lobeview refuses; the message names the file (or 'inline JSON') and why."""


def read_regular_file(path: str | Path, what: str, max_bytes: int) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (checked before reading, and again
    on the opened file: the path may have been swapped in between)."""
    from lobeview.core.trust import Limits, UntrustedReferenceError, check_regular_file

    try:
        check_regular_file(Path(path), what, Limits(max_file_bytes=max_bytes))
    except (UntrustedReferenceError, FileNotFoundError) as exc:
        raise JSONInputError(str(exc)) from None
    try:
        # O_NONBLOCK: a FIFO swapped in after the check opens at once instead of waiting forever.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise JSONInputError(f"{what} {path}: cannot read it ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise JSONInputError(f"{what} {path}: not a regular file: refused")
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise JSONInputError(f"{what} {path}: more than the {max_bytes} bytes allowed")
    return data


def _number(text: str, kind, where: str):
    if len(text) > MAX_NUMBER_CHARS:
        raise JSONInputError(f"{where}: a number of {len(text)} characters ({quoted(text, 24)}), more than the "
                             f"{MAX_NUMBER_CHARS} allowed")  # fmt: skip
    value = kind(text)
    if isinstance(value, float) and not math.isfinite(value):
        raise JSONInputError(f"{where}: the number {quoted(text, 24)} is not finite")
    return value


def _not_json(name: str, where: str):
    raise JSONInputError(f"{where}: {name} is not a JSON number (use a finite number)")


def _depth(value) -> int:
    """Nesting depth of parsed JSON, without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, depth)
            if depth <= MAX_JSON_DEPTH:  # deeper is refused anyway: stop looking
                stack.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def parse_json_text(text: str, where: str):
    """Parse ``text`` under the module's limits; ``where`` opens every message ('--script
    FILE', 'inline material JSON')."""
    try:
        value = json.loads(
            text,
            parse_int=lambda s: _number(s, int, where),
            parse_float=lambda s: _number(s, float, where),
            parse_constant=lambda name: _not_json(name, where),
        )
    except json.JSONDecodeError as exc:
        raise JSONInputError(f"{where}: not valid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise JSONInputError(f"{where}: nested deeper than the {MAX_JSON_DEPTH} levels allowed") from None
    if _depth(value) > MAX_JSON_DEPTH:
        raise JSONInputError(f"{where}: nested deeper than the {MAX_JSON_DEPTH} levels allowed")
    return value


def read_json_file(path: str | Path, what: str, max_bytes: int = MAX_JSON_BYTES):
    """Parsed JSON of the file ``path`` (``what``: how the user gave it, '--script', 'camera
    path', 'material file'), under the module's limits; JSONInputError otherwise."""
    data = read_regular_file(path, what, max_bytes)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise JSONInputError(f"{what} {path}: not UTF-8 text (byte {exc.start})") from None
    return parse_json_text(text, f"{what} {path}")
