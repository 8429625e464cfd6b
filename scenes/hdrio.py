"""Reading and writing linear HDR images: OpenEXR (through the OpenEXR package) and Radiance
RGBE .hdr (a small reader/writer here: the format is a header plus run-length-encoded 4-byte
scanlines, and the alternatives need native image libraries outside PyPI wheels).

All images are float32 arrays of shape (height, width, 3), row 0 at the top, linear radiance.
Every loader error names the file; :func:`sanitize_radiance` replaces NaN/Inf/negative texels
with 0 and reports how many it fixed.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lobeview.core.trust import BudgetError, LoadBudget, UntrustedReferenceError, check_regular_file

HDR_EXTENSIONS = (".exr", ".hdr", ".pic")


class HDRImageError(ValueError):
    """An HDR image that cannot be read, with the file name in the message."""


class HDRImageWarning(UserWarning):
    """A documented fallback was applied to an HDR image (e.g. NaN texels set to 0)."""


def read_hdr_image(path: str | Path, budget: LoadBudget | None = None) -> np.ndarray:
    """Read an EXR or Radiance image. Only regular files within the size limit are opened, and
    the declared resolution is checked against ``budget`` (default: the default limits) before
    the pixels are allocated."""
    path = Path(path)
    budget = budget if budget is not None else LoadBudget(source=str(path))
    suffix = path.suffix.lower()
    if suffix not in HDR_EXTENSIONS:
        raise HDRImageError(f"{path}: unsupported HDR format {suffix!r}; use one of {HDR_EXTENSIONS}")
    try:
        check_regular_file(path, "HDR image", budget.limits)
        if suffix == ".exr":
            return _read_exr(path, budget)
        return _read_rgbe(path, budget)
    except FileNotFoundError:
        raise HDRImageError(f"{path}: no such file") from None
    except (UntrustedReferenceError, BudgetError) as exc:
        raise HDRImageError(str(exc)) from None


def write_hdr_image(path: str | Path, image: np.ndarray) -> Path:
    path = Path(path)
    image = np.asarray(image, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got shape {image.shape}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".exr":
        _write_exr(path, image)
    elif path.suffix.lower() in (".hdr", ".pic"):
        _write_rgbe(path, image)
    else:
        raise HDRImageError(f"{path}: unsupported HDR format; use .exr or .hdr")
    return path


# -- OpenEXR ----------------------------------------------------------------------------------


def _read_exr(path: Path, budget: LoadBudget) -> np.ndarray:
    import OpenEXR

    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            low, high = (np.asarray(corner, dtype=np.int64) for corner in exr.header()["dataWindow"])
    except Exception as exc:
        raise HDRImageError(f"{path}: cannot read EXR header: {exc}") from None
    width, height = int(high[0] - low[0] + 1), int(high[1] - low[1] + 1)
    # 4 channels x float32 for what OpenEXR decodes, 3 x float32 for the result.
    budget.check_image(width, height, 7, 4, f"EXR {path.name}")
    try:
        with OpenEXR.File(str(path)) as exr:
            channels = exr.channels()
            if "RGB" in channels:
                rgb = np.asarray(channels["RGB"].pixels, dtype=np.float32)
            elif "RGBA" in channels:
                rgb = np.asarray(channels["RGBA"].pixels, dtype=np.float32)[..., :3]
            elif all(c in channels for c in "RGB"):
                rgb = np.stack([np.asarray(channels[c].pixels, np.float32) for c in "RGB"], -1)
            elif "Y" in channels:
                y = np.asarray(channels["Y"].pixels, dtype=np.float32)
                rgb = np.repeat(y[..., None], 3, axis=-1)
            else:
                raise HDRImageError(f"{path}: no R, G, B (or Y) channels in the EXR (has {sorted(channels)})")
    except HDRImageError:
        raise
    except Exception as exc:  # OpenEXR raises RuntimeError/OSError variants for corrupt files
        raise HDRImageError(f"{path}: cannot read EXR: {exc}") from None
    if rgb.ndim != 3:
        raise HDRImageError(f"{path}: unexpected EXR pixel layout {rgb.shape}")
    return np.ascontiguousarray(rgb, dtype=np.float32)


def _write_exr(path: Path, image: np.ndarray) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as exr:
        exr.write(str(path))


# -- Radiance RGBE ----------------------------------------------------------------------------

_RESOLUTION = re.compile(rb"^([-+])Y (\d+) ([-+])X (\d+)$")


def _read_rgbe(path: Path, budget: LoadBudget) -> np.ndarray:
    data = path.read_bytes()
    pos = 0
    header_lines = []
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise HDRImageError(f"{path}: truncated Radiance header")
        line = data[pos:end].strip()
        pos = end + 1
        if line == b"":
            break
        header_lines.append(line)
    if not header_lines or not header_lines[0].startswith(b"#?"):
        raise HDRImageError(f"{path}: not a Radiance HDR file (missing '#?' signature)")
    for line in header_lines:
        if line.startswith(b"FORMAT=") and line != b"FORMAT=32-bit_rle_rgbe":
            raise HDRImageError(f"{path}: unsupported Radiance format {line.decode(errors='replace')}")
    end = data.find(b"\n", pos)
    match = _RESOLUTION.match(data[pos:end].strip()) if end >= 0 else None
    if match is None:
        raise HDRImageError(f"{path}: unsupported or missing resolution line (need '-Y H +X W')")
    if match.group(1) != b"-" or match.group(3) != b"+":
        raise HDRImageError(f"{path}: only the standard '-Y H +X W' orientation is supported")
    height, width = int(match.group(2)), int(match.group(4))
    # 4 bytes RGBE + 3 x float64 while decoding + 3 x float32 result per texel.
    budget.check_image(width, height, 1, 4 + 24 + 12, f"Radiance image {path.name}")
    # Lower bound on the pixel bytes: 4 per flat texel or per RLE scanline header, and at
    # least 2 bytes per 128-texel run in each of the 4 channels.
    if len(data) - end < height * max(4, 8 * (width // 128)):
        raise HDRImageError(
            f"{path}: {width}x{height} pixels declared but the pixel data is truncated to {len(data) - end} bytes"
        )
    pos = end + 1
    rgbe = np.empty((height, width, 4), dtype=np.uint8)
    buf = np.frombuffer(data, dtype=np.uint8)
    for y in range(height):
        pos = _read_scanline(buf, pos, width, rgbe[y], path, y)
    return _rgbe_to_float(rgbe)


def _read_scanline(buf: np.ndarray, pos: int, width: int, out: np.ndarray, path: Path, y: int) -> int:
    if pos + 4 > len(buf):
        raise HDRImageError(f"{path}: truncated pixel data at scanline {y}")
    new_rle = 8 <= width < 32768 and buf[pos] == 2 and buf[pos + 1] == 2 and not (buf[pos + 2] & 0x80)
    if not new_rle:
        # Flat (uncompressed) scanline; old-style RLE is not produced by current tools.
        end = pos + 4 * width
        if end > len(buf):
            raise HDRImageError(f"{path}: truncated pixel data at scanline {y}")
        out[:] = buf[pos:end].reshape(width, 4)
        return end
    if (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) != width:
        raise HDRImageError(f"{path}: corrupt scanline {y} (length mismatch)")
    pos += 4
    for channel in range(4):
        x = 0
        while x < width:
            if pos >= len(buf):
                raise HDRImageError(f"{path}: truncated pixel data at scanline {y}")
            count = int(buf[pos])
            pos += 1
            if count > 128:  # a run
                count -= 128
                if x + count > width or pos >= len(buf):
                    raise HDRImageError(f"{path}: corrupt run-length data at scanline {y}")
                out[x : x + count, channel] = buf[pos]
                pos += 1
            else:  # literal bytes
                if count == 0 or x + count > width or pos + count > len(buf):
                    raise HDRImageError(f"{path}: corrupt run-length data at scanline {y}")
                out[x : x + count, channel] = buf[pos : pos + count]
                pos += count
            x += count
    return pos


def _rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    exponent = rgbe[..., 3].astype(np.int32)
    # value = mantissa / 256 * 2^(e - 128), zero when e == 0: the decoding of stb_image,
    # OpenCV and imageio (Radiance's own adds 0.5 to the mantissa; the difference is < 0.4 %
    # and only this convention keeps black texels exactly 0).
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0).astype(np.float64)
    rgb = rgbe[..., :3].astype(np.float64) * scale[..., None]
    return rgb.astype(np.float32)


def _write_rgbe(path: Path, image: np.ndarray) -> None:
    """Flat (uncompressed) RGBE; readable by every Radiance-compatible tool."""
    img = np.clip(np.nan_to_num(image.astype(np.float64), nan=0.0, posinf=0.0), 0.0, None)
    brightest = img.max(axis=-1)
    mantissa, exponent = np.frexp(brightest)
    scale = np.where(brightest > 1e-32, mantissa * 256.0 / np.where(brightest > 0, brightest, 1.0), 0.0)
    rgbe = np.zeros(img.shape[:2] + (4,), dtype=np.uint8)
    rgbe[..., :3] = np.clip(np.floor(img * scale[..., None]), 0, 255).astype(np.uint8)
    rgbe[..., 3] = np.where(brightest > 1e-32, exponent + 128, 0).astype(np.uint8)
    h, w = img.shape[:2]
    header = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode()
    path.write_bytes(header + rgbe.tobytes())


# -- sanitising ----------------------------------------------------------------------------------


@dataclass
class SanitizeReport:
    non_finite: int = 0  # texels with a NaN/Inf channel
    negative: int = 0  # texels with a negative channel
    energy_before: tuple = (0.0, 0.0, 0.0)  # per-channel sum of the finite values, signed
    energy_after: tuple = (0.0, 0.0, 0.0)

    @property
    def changed(self) -> bool:
        return bool(self.non_finite or self.negative)

    @property
    def relative_energy_change(self) -> float:
        before, after = sum(self.energy_before), sum(self.energy_after)
        return (after - before) / before if before > 0 else 0.0


def _box3(image: np.ndarray) -> np.ndarray:
    """3x3 box sum per channel, zero outside (wrap would be right for an equirect's longitude,
    but the repair must also serve lightmaps; the borders are a one-texel detail)."""
    padded = np.pad(image, ((1, 1), (1, 1), (0, 0)))
    h, w = image.shape[:2]
    return sum(padded[dy : dy + h, dx : dx + w] for dy in range(3) for dx in range(3))


def repair_negative(values: np.ndarray) -> np.ndarray:
    """Clamp negative texels to 0 without adding energy (per channel, float64 in and out).

    Negative texels in real captures are the ringing of a resampling filter (Lanczos, DWAB) next
    to bright features; clamping alone adds their magnitude as light (+5 to +13 % measured on
    resampled HDRIs with a sun). Each negative texel's deficit is taken instead from the positive
    texels of its 3x3 neighbourhood in proportion to their value (where the ringing came from),
    which keeps the energy local; what a neighbourhood cannot give (no positive neighbour) is
    taken from the whole channel by one scale factor. The per-channel sum of the result equals
    the signed sum of the input whenever that sum is positive."""
    deficit = np.maximum(-values, 0.0)
    clamped = np.maximum(values, 0.0)
    neighbourhood = _box3(clamped)
    share = np.where(neighbourhood > 0, deficit / np.where(neighbourhood > 0, neighbourhood, 1.0), 0.0)
    removal = np.minimum(_box3(share), 1.0)  # fraction of each positive texel given up
    repaired = clamped * (1.0 - removal)
    target = values.sum(axis=(0, 1))
    current = repaired.sum(axis=(0, 1))
    scale = np.where((current > 0) & (target > 0), target / np.where(current > 0, current, 1.0), 1.0)
    scale = np.where(target <= 0, 0.0, scale)  # a channel with no net light stays dark
    return repaired * np.minimum(scale, 1.0)[None, None, :]


def _repair_non_finite(image: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Texels with NaN/Inf channels: a channel lost to a half-float overflow (+Inf) or a broken
    encoder (NaN) takes the brightest finite channel of the same texel, so a sun that survives in
    one channel stays a (white) sun instead of a coloured rim; a texel with no finite channel
    becomes 0."""
    finite = np.isfinite(image)
    finite_max = np.max(np.where(finite, image, -np.inf), axis=-1, keepdims=True)
    finite_max = np.where(np.isfinite(finite_max), np.maximum(finite_max, 0.0), 0.0)
    fixed = np.where(finite, image, finite_max)
    return np.where(bad[..., None], fixed, image)


def sanitize_radiance(
    image: np.ndarray, name: str, negative_tolerance: float = 0.0
) -> tuple[np.ndarray, SanitizeReport]:
    """Make radiance finite and non-negative, warning with the counts and the energy change.

    NaN/Inf channels: see :func:`_repair_non_finite`. Negative values: :func:`repair_negative`,
    which conserves each channel's energy instead of adding the clamped amount. Warnings about
    negatives are silenced when none is below ``-negative_tolerance`` (lossy EXRs hold tiny ones).
    """
    image = np.asarray(image, dtype=np.float32)
    finite = np.isfinite(image)
    bad = ~np.all(finite, axis=-1)
    report = SanitizeReport(non_finite=int(np.count_nonzero(bad)))
    clean = _repair_non_finite(image, bad).astype(np.float64) if report.non_finite else image.astype(np.float64)
    report.energy_before = tuple(float(v) for v in clean.sum(axis=(0, 1)))
    negative = clean < 0.0
    report.negative = int(np.count_nonzero(np.any(negative, axis=-1)))
    if report.negative:
        most_negative = float(clean.min())
        clean = repair_negative(clean)
    report.energy_after = tuple(float(v) for v in clean.sum(axis=(0, 1)))
    clean = np.minimum(clean, np.finfo(np.float32).max).astype(np.float32)
    if report.non_finite:
        warnings.warn(
            f"{name}: {report.non_finite} texels with NaN/Inf channels repaired (from the texel's brightest "
            "finite channel, else 0)",
            HDRImageWarning,
            stacklevel=2,
        )
    if report.negative and most_negative < -negative_tolerance:
        warnings.warn(
            f"{name}: {report.negative} texels with negative values (down to {most_negative:.3g}) set to 0 and their "
            f"deficit taken from their neighbours; energy change {100 * report.relative_energy_change:+.3f} % "
            "(clamping alone would add it)",
            HDRImageWarning,
            stacklevel=2,
        )
    return clean, report
