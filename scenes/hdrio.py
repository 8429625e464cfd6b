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

HDR_EXTENSIONS = (".exr", ".hdr", ".pic")


class HDRImageError(ValueError):
    """An HDR image that cannot be read, with the file name in the message."""


class HDRImageWarning(UserWarning):
    """A documented fallback was applied to an HDR image (e.g. NaN texels set to 0)."""


def read_hdr_image(path: str | Path) -> np.ndarray:
    path = Path(path)
    if not path.exists():
        raise HDRImageError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".exr":
        return _read_exr(path)
    if suffix in (".hdr", ".pic"):
        return _read_rgbe(path)
    raise HDRImageError(f"{path}: unsupported HDR format {suffix!r}; use one of {HDR_EXTENSIONS}")


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


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR

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


def _read_rgbe(path: Path) -> np.ndarray:
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

    @property
    def changed(self) -> bool:
        return bool(self.non_finite or self.negative)


def sanitize_radiance(
    image: np.ndarray, name: str, negative_tolerance: float = 0.0
) -> tuple[np.ndarray, SanitizeReport]:
    """Replace NaN/Inf texel values and negative values by 0 (documented fallback) and warn
    with the counts. Lossy-compressed EXRs (DWAB) routinely hold tiny negatives."""
    image = np.asarray(image, dtype=np.float32)
    finite = np.isfinite(image)
    report = SanitizeReport(non_finite=int(np.count_nonzero(~np.all(finite, axis=-1))))
    clean = np.where(finite, image, 0.0)
    negative = clean < 0.0
    report.negative = int(np.count_nonzero(np.any(negative, axis=-1)))
    clean = np.where(negative, 0.0, clean).astype(np.float32)
    if report.non_finite:
        warnings.warn(
            f"{name}: {report.non_finite} texels with NaN/Inf values set to 0",
            HDRImageWarning,
            stacklevel=2,
        )
    if report.negative:
        most_negative = float(image[finite].min()) if np.any(finite) else 0.0
        if most_negative < -negative_tolerance:
            warnings.warn(
                f"{name}: {report.negative} texels with negative values (down to {most_negative:.3g}) clamped to 0",
                HDRImageWarning,
                stacklevel=2,
            )
    return clean, report
