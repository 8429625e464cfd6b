"""The trust boundary for files that scenes reference, and the limits checked before allocation.

A scene file (glTF/GLB, its images, lightmaps and material extras) comes from someone else: it
may name only files inside its own folder. :func:`resolve_reference` is the one place a URI from
such a file becomes a path:

- ``data:`` URIs are decoded by the caller and never touch the file system;
- other schemes (``file:``, ``http:``...), absolute paths (``/etc/passwd``, ``//host/x``,
  ``C:\\x``) and paths that leave the folder (``../..``, a symlink pointing out) are refused,
  unless the user opted in with ``--allow-outside-references`` (:class:`Limits.allow_outside`);
- whatever the opt-in, only regular files are opened: devices, FIFOs and sockets
  (``/dev/zero``, ``/proc/self/...`` pseudo files report size 0 and are refused as empty) would
  block or never end;
- a file's size is checked against :attr:`Limits.max_file_bytes` before it is read.

:class:`LoadBudget` counts the bytes a load allocates for decoded arrays (accessors, images) and
refuses the load with a clear message once it passes :attr:`Limits.memory_budget_bytes`, so a
file that declares a billion vertices or a 100000 x 100000 image is refused, not allocated.

This module imports nothing of lobeview (core/ is the ground floor).
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

GIB = 1 << 30
MIB = 1 << 20

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")


class UntrustedReferenceError(ValueError):
    """A scene file names a file it may not read (outside its folder, a device, too large)."""


class BudgetError(ValueError):
    """A load would allocate more than its memory budget."""


@dataclass(frozen=True)
class Limits:
    """What one scene load may read and allocate. The defaults fit a workstation scene and a
    24 GiB machine; the CLI exposes ``--allow-outside-references`` and ``--memory-budget``."""

    allow_outside: bool = False
    max_file_bytes: int = 2 * GIB  # one referenced file (buffer, image, lightmap)
    max_image_pixels: int = 16384 * 16384  # declared width x height of one image
    max_image_side: int = 65536
    memory_budget_bytes: int = 6 * GIB  # decoded arrays of one load (accessors + images)
    max_nodes_visited: int = 1_000_000
    # Drawable objects (mesh primitives placed by nodes) and nodes of one glTF scene: each object
    # costs Python work per load and per frame and, with a cube map, draws of every other object
    # (100 000 nodes in a 5 MB file ran for minutes, issue 43); a realistic building is well below.
    max_objects: int = 5000
    max_nodes: int = 100_000


DEFAULT_LIMITS = Limits()


def _describe_size(n: int) -> str:
    if n >= GIB:
        return f"{n / GIB:.2f} GiB"
    return f"{n / MIB:.1f} MiB" if n >= MIB else f"{n} bytes"  # "0.0 MiB exceeds 0.0 MiB" said nothing


def check_regular_file(path: Path, what: str, limits: Limits = DEFAULT_LIMITS) -> int:
    """Size in bytes of a regular file, or :class:`UntrustedReferenceError` naming why not."""
    try:
        info = path.stat()  # follows symlinks: the target is what would be read
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {path}: no such file") from None
    except OSError as exc:
        raise UntrustedReferenceError(f"{what} {path}: cannot stat ({exc.strerror})") from None
    if not stat.S_ISREG(info.st_mode):
        raise UntrustedReferenceError(f"{what} {path}: not a regular file (device, FIFO, socket or folder); refused")
    if info.st_size > limits.max_file_bytes:
        raise UntrustedReferenceError(
            f"{what} {path}: {_describe_size(info.st_size)} exceeds the "
            f"{_describe_size(limits.max_file_bytes)} limit for one file"
        )
    return info.st_size


def resolve_reference(base_dir: Path, uri: str, what: str, limits: Limits = DEFAULT_LIMITS) -> Path:
    """The path a scene file's relative ``uri`` names inside ``base_dir``; raises
    :class:`UntrustedReferenceError` for anything outside (see the module docstring) and
    :class:`FileNotFoundError` when the file does not exist."""
    if not isinstance(uri, str) or not uri:
        raise UntrustedReferenceError(f"{what}: empty or non-string URI {uri!r}")
    if "\x00" in uri:
        raise UntrustedReferenceError(f"{what}: URI contains a NUL byte; refused")
    if uri.startswith("data:"):
        raise ValueError("data: URIs are decoded by the caller, not resolved")
    decoded = unquote(uri)  # glTF URIs are percent-encoded (RFC 3986)
    if "\x00" in decoded:
        raise UntrustedReferenceError(f"{what}: URI contains a NUL byte; refused")
    outside = (
        _SCHEME.match(decoded) is not None  # file:, http:, C: ...
        or decoded.startswith(("/", "\\"))
        or os.path.isabs(decoded)
    )
    base = Path(base_dir).resolve()
    candidate = base / decoded.replace("\\", "/")
    if not outside:
        try:
            resolved = candidate.resolve()
        except (OSError, RuntimeError) as exc:  # symlink loop
            raise UntrustedReferenceError(f"{what} {uri!r}: cannot resolve ({exc})") from None
        outside = not resolved.is_relative_to(base)
    if outside and not limits.allow_outside:
        raise UntrustedReferenceError(
            f"{what} {uri!r} points outside the scene's folder {base}; refused "
            "(a scene may reference only files in its own folder; pass --allow-outside-references "
            "to permit it for a scene you trust)"
        )
    if outside:  # opted in: take the URI as the user's file system sees it
        if _SCHEME.match(decoded) and not decoded.lower().startswith("file:"):
            raise UntrustedReferenceError(f"{what} {uri!r}: only local files can be read")
        local = decoded[5:] if decoded.lower().startswith("file:") else decoded
        candidate = Path(local) if os.path.isabs(local) else base / local
    check_regular_file(candidate, what, limits)
    return candidate


def read_reference(base_dir: Path, uri: str, what: str, limits: Limits = DEFAULT_LIMITS) -> bytes:
    """The bytes of a referenced file, after :func:`resolve_reference` and the size check."""
    path = resolve_reference(base_dir, uri, what, limits)
    with open(path, "rb") as fh:
        # Read at most the checked size + 1: a file that grows while being read is refused
        # instead of read without end.
        data = fh.read(limits.max_file_bytes + 1)
    if len(data) > limits.max_file_bytes:
        raise UntrustedReferenceError(f"{what} {path}: grew past the size limit while being read")
    return data


class LoadBudget:
    """Bytes allocated for decoded arrays during one load, refused past the budget."""

    def __init__(self, limits: Limits = DEFAULT_LIMITS, source: str = ""):
        self.limits = limits
        self.source = source
        self.used = 0

    def take(self, nbytes: int, what: str) -> None:
        if nbytes < 0:
            raise BudgetError(f"{self.source}: {what} declares a negative size")
        if self.used + nbytes > self.limits.memory_budget_bytes:
            raise BudgetError(
                f"{self.source}: {what} needs {_describe_size(nbytes)}, which would take this load past its "
                f"memory budget of {_describe_size(self.limits.memory_budget_bytes)} "
                f"({_describe_size(self.used)} used); raise it with --memory-budget if the scene is really that large"
            )
        self.used += nbytes

    def check_image(self, width: int, height: int, channels: int, itemsize: int, what: str) -> None:
        """Refuse an image by its declared size, before its pixels are decoded."""
        limits = self.limits
        if width <= 0 or height <= 0:
            raise BudgetError(f"{self.source}: {what} declares an empty size {width}x{height}")
        if width > limits.max_image_side or height > limits.max_image_side or width * height > limits.max_image_pixels:
            raise BudgetError(
                f"{self.source}: {what} declares {width}x{height} pixels; the limit is "
                f"{limits.max_image_pixels} pixels and {limits.max_image_side} per side"
            )
        self.take(width * height * channels * itemsize, what)


def parse_budget(text: str) -> int:
    """'6G', '512M', '1.5GiB' or a byte count -> bytes (for --memory-budget)."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([KMGT]?)(i?B)?\s*", text, re.IGNORECASE)
    if not match:
        raise ValueError(f"memory budget {text!r}: expected a size such as 6G, 512M or 1.5GiB")
    scale = {"": 1, "K": 1 << 10, "M": MIB, "G": GIB, "T": 1 << 40}[match.group(2).upper()]
    value = int(float(match.group(1)) * scale)
    if value < MIB:
        raise ValueError(f"memory budget {text!r}: at least 1M")
    return value
