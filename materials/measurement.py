"""Scattering measurements: the thesis' goniophotometer tuples, MERL tables, virtual measurements.

A :class:`Measurement` is a list of tuples (wi, wo, p) with p = f_s(wi, wo) |cos theta_o| the
*transfer probability* density of thesis Eq. 2.4 (per steradian of wo), plus the solid angle
``weight`` each tuple represents (the w of thesis Eq. 3.7). Directions live in the sample's
frame: z = surface normal, x = the tangent (the brushing direction of an anisotropic sample).
``wi`` points to the light, ``wo`` to the detector; a detector below the surface (wo.z < 0) is a
transmission measurement.

Three sources:

- :func:`read_csv` / :func:`write_csv`: lobeview's plain goniophotometer format (docs/guide.md
  "Measured materials"): a header line ``theta_i,phi_i,theta_o,phi_o,p`` (or ``p_r,p_g,p_b``,
  optionally ``weight``), angles in degrees, theta_o > 90 for the transmission hemisphere,
  ``#`` comment lines anywhere.
- :func:`read_merl` / :func:`write_merl`: the MERL isotropic BRDF database's binary layout
  (Matusik et al. 2003): three int32 dimensions (90, 90, 180) = (theta_h, theta_d, phi_d), then
  3 x 1 458 000 float64 values, channel-major (all red, all green, all blue), each scaled by
  1/1500, 1.15/1500, 1.66/1500 for R, G, B. theta_h is stored non-linearly
  (index = sqrt(theta_h / 90 deg) x 90), phi_d over [0, 180) deg by reciprocity. Negative
  entries mean "not measured" and are masked. :func:`merl_measurement` turns a table into
  tuples (a subsampled set of its cells).
- :func:`lobeview.materials.virtual.virtual_measurement` (materials/virtual.py): any lobeview
  material evaluated at a goniophotometer's directions (the thesis' incidence angles by
  default), with optional noise and outliers.

Every reader validates before it allocates (file size against the declared layout, row count)
and refuses NaN/Inf with the line or cell that holds it.
"""

from __future__ import annotations

import csv
import io
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lobeview.core.trust import MIB, Limits, check_regular_file

from .lobe_fit import LUMINANCE
from .vec import mirror_z, spherical_direction

#: The thesis' goniophotometer incidence angles (Fig. 3.11/3.17: anisotropic samples).
THESIS_THETA_I_DEG = (0.0, 5.0, 20.0, 35.0, 50.0, 65.0)
THESIS_PHI_I_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
#: Incidence angles of the thesis' isotropic white-foil set (Fig. 3.14).
THESIS_ISOTROPIC_THETA_I_DEG = (0.0, 5.0, 19.0, 33.0, 47.0, 61.0, 75.0)

MAX_CSV_BYTES = 512 * MIB
MAX_TUPLES = 20_000_000
# A virtual goniophotometer's tuples, counted before anything is allocated: each costs ~380 bytes
# through the fit (measured: 20 M CSV rows reached 7.7 GB), so 4 M stay near 1.5 GB.
MAX_VIRTUAL_TUPLES = 4_000_000
# Largest transfer probability p = f |cos| accepted [1/sr]: a mirror lobe scanned at 0.02 degrees
# reaches ~1e7; beyond 1e9 the fit's sums of p^2 x weight lose all precision (1e308 overflowed to
# an infinite error that was then reported as 0).
MAX_TRANSFER = 1e9
MAX_WEIGHT = 4.0 * np.pi  # a tuple's solid angle cannot exceed the sphere's

MERL_DIMS = (90, 90, 180)  # theta_h, theta_d, phi_d
MERL_SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
MERL_CELLS = MERL_DIMS[0] * MERL_DIMS[1] * MERL_DIMS[2]
MERL_FILE_BYTES = 3 * 4 + 3 * MERL_CELLS * 8


class MeasurementError(ValueError):
    """A measurement file or array that cannot be used, with the reason and where."""


@dataclass
class Measurement:
    """Tuples (wi, wo, p) in the sample frame; see the module docstring for conventions."""

    wi: np.ndarray  # (N, 3) unit, towards the light, wi.z > 0
    wo: np.ndarray  # (N, 3) unit, towards the detector; wo.z < 0: transmission
    p: np.ndarray  # (N, C) transfer probability f |cos theta_o|, C = 1 or 3 (linear RGB)
    weight: np.ndarray  # (N,) solid angle each tuple represents (Eq. 3.7's w)
    name: str = "measurement"
    source: str = ""
    notes: list[str] = field(default_factory=list)

    def __post_init__(self):
        n = len(self.wi)
        self.wi = np.asarray(self.wi, dtype=np.float64).reshape(n, 3)
        self.wo = np.asarray(self.wo, dtype=np.float64).reshape(n, 3)
        self.p = np.asarray(self.p, dtype=np.float64).reshape(n, -1)
        self.weight = np.asarray(self.weight, dtype=np.float64).reshape(n)
        if self.p.shape[1] not in (1, 3):
            raise MeasurementError(f"{self.name}: p must have 1 or 3 channels, got {self.p.shape[1]}")
        for label, arr in (("wi", self.wi), ("wo", self.wo), ("p", self.p), ("weight", self.weight)):
            bad = ~np.isfinite(arr).reshape(n, -1).all(axis=1)
            if bad.any():
                raise MeasurementError(f"{self.name}: {label} is NaN or infinite in tuple {int(np.argmax(bad))}")
        if (self.p < 0).any():
            raise MeasurementError(
                f"{self.name}: negative transfer probability in tuple {int(np.argmax((self.p < 0).any(1)))}"
            )
        if (self.weight < 0).any():
            raise MeasurementError(f"{self.name}: negative weight in tuple {int(np.argmax(self.weight < 0))}")
        if (self.p > MAX_TRANSFER).any():
            raise MeasurementError(
                f"{self.name}: transfer probability above {MAX_TRANSFER:g} in tuple "
                f"{int(np.argmax((self.p > MAX_TRANSFER).any(1)))} (p = f |cos theta_o| in 1/sr)"
            )
        if (self.weight > MAX_WEIGHT).any():
            raise MeasurementError(
                f"{self.name}: weight above 4 pi (a solid angle) in tuple {int(np.argmax(self.weight > MAX_WEIGHT))}"
            )
        if (self.wi[:, 2] <= 0).any():
            raise MeasurementError(
                f"{self.name}: incident direction at or below the surface in tuple "
                f"{int(np.argmax(self.wi[:, 2] <= 0))} (theta_i must be < 90 deg)"
            )
        if n == 0:
            raise MeasurementError(f"{self.name}: no tuples")

    def __len__(self) -> int:
        return len(self.wi)

    @property
    def channels(self) -> int:
        return self.p.shape[1]

    @property
    def transmission(self) -> np.ndarray:
        """Mask of tuples whose detector lies below the surface."""
        return self.wo[:, 2] < 0.0

    @property
    def luminance(self) -> np.ndarray:
        """The scalar the shape fit works on: p itself, or Rec. 709 luminance of RGB p, (N,)."""
        return self.p[:, 0] if self.channels == 1 else self.p @ LUMINANCE

    def incidences(self) -> np.ndarray:
        """Distinct incident directions as (theta_i, phi_i) in degrees, rounded to 0.01."""
        theta, phi = angles_deg(self.wi)
        return np.unique(np.round(np.stack([theta, phi], axis=1), 2), axis=0)


def angles_deg(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle from +z and azimuth from +x (in [0, 360)) of unit vectors, in degrees."""
    theta = np.degrees(np.arccos(np.clip(w[..., 2], -1.0, 1.0)))
    phi = np.degrees(np.arctan2(w[..., 1], w[..., 0])) % 360.0
    return theta, phi


def sample_frame_eval(bsdf, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The BSDF at directions in the sample's frame (x = the tangent, renderer convention): a
    BSDF's own x axis is its anisotropy direction, the tangent turned by ``tangent_rotation``
    about the normal (materials/gltf.py anisotropy_frame), so the directions are turned into it."""
    r = float(getattr(bsdf, "tangent_rotation", 0.0))
    if r:
        c, s = math.cos(r), math.sin(r)
        to_local = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        wi, wo = wi @ to_local.T, wo @ to_local.T
    return bsdf.eval(wi, wo)


def renderer_pair(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) in the renderer's convention (viewer above the surface): a transmission tuple,
    light above and detector below, is mirrored through the surface plane. The thin-surface
    models (thesis Eq. 3.5, glTF thin transmission) are symmetric under that mirror, so the BSDF
    value is unchanged."""
    below = wo[:, 2] < 0.0
    wi = np.where(below[:, None], mirror_z(wi), wi)
    wo = np.where(below[:, None], mirror_z(wo), wo)
    return wi, wo


# -- lobeview's goniophotometer CSV ----------------------------------------------------------------

_REQUIRED = ("theta_i", "phi_i", "theta_o", "phi_o")
# Columns with a largest magnitude, named in the error with the line.
_VALUE_LIMITS = (
    *((name, MAX_TRANSFER, f"{MAX_TRANSFER:g} (p = f |cos theta_o| in 1/sr)") for name in ("p", "p_r", "p_g", "p_b")),
    ("weight", MAX_WEIGHT, "4 pi (a solid angle)"),
)


CSV_CHUNK_ROWS = 1 << 16  # rows parsed at once: memory for the text is one chunk's, not the file's


def read_csv(path, negative: str = "error", limits: Limits | None = None) -> Measurement:
    """Read a goniophotometer CSV (see the module docstring and docs/guide.md "Measured materials").

    ``negative``: what to do with negative p (background-subtracted noise): ``"error"``
    (default), ``"clamp"`` to 0 or ``"mask"`` (drop the tuple), both with a warning that counts
    them. Missing cells, NaN and Inf are always errors naming the line.

    Streamed: CSV_CHUNK_ROWS lines at a time are parsed (numpy's C parser; a chunk it refuses is
    read again line by line to name the line), checked and turned into the measurement's arrays,
    so the memory is the kept tuples' arrays plus one chunk (reading the whole text and a list of
    its lines first took 7.7 GB for a 20 M row file within the limits).
    """
    path = Path(path)
    size = check_regular_file(path, "measurement", limits or Limits(max_file_bytes=MAX_CSV_BYTES))
    if size == 0:
        raise MeasurementError(f"{path}: empty file")
    if negative not in ("error", "clamp", "mask"):
        raise ValueError(f"negative must be 'error', 'clamp' or 'mask', got {negative!r}")
    parts: list[tuple] = []
    negatives = rows = 0
    try:
        with open(path, encoding="utf-8", newline="") as handle:
            lines = _data_lines(handle)
            header_line, header = next(lines, (0, None))
            if header is None:
                raise MeasurementError(f"{path}: no header line (expected {','.join(_REQUIRED)},p)")
            columns, p_columns = _csv_columns(path, header_line, header)
            chunk: list[tuple[int, str]] = []
            for numbered in lines:
                chunk.append(numbered)
                if len(chunk) == CSV_CHUNK_ROWS:
                    rows += len(chunk)
                    if rows > MAX_TUPLES:
                        raise MeasurementError(f"{path}: more than {MAX_TUPLES} rows (the limit)")
                    negatives += _csv_chunk(path, chunk, columns, p_columns, negative, parts)
                    chunk = []
            if chunk:
                rows += len(chunk)
                if rows > MAX_TUPLES:
                    raise MeasurementError(f"{path}: more than {MAX_TUPLES} rows (the limit)")
                negatives += _csv_chunk(path, chunk, columns, p_columns, negative, parts)
    except UnicodeDecodeError as exc:
        raise MeasurementError(f"{path}: not UTF-8 text ({exc})") from None
    if not rows:
        raise MeasurementError(f"{path}: header but no data rows")
    if negatives:
        warnings.warn(
            f"{path}: {negatives} tuples with negative p {'clamped to 0' if negative == 'clamp' else 'dropped'}",
            stacklevel=2,
        )
    wi, wo, p, weight = (np.concatenate([part[k] for part in parts]) for k in range(4))
    return Measurement(wi, wo, p, weight, name=path.stem, source=str(path))


def _data_lines(handle):
    """(line number, line) of every line that is neither blank nor a comment."""
    for number, line in enumerate(handle, start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            yield number, line


def _csv_columns(path: Path, header_line: int, header: str) -> tuple[list[str], list[str]]:
    """The header's column names and the p columns among them, checked."""
    columns = [c.strip().lower() for c in next(csv.reader([header]))]
    repeated = sorted({c for c in columns if columns.count(c) > 1})
    if repeated:
        raise MeasurementError(f"{path}:{header_line}: columns {repeated} appear more than once")
    missing = [c for c in _REQUIRED if c not in columns]
    if missing:
        raise MeasurementError(
            f"{path}:{header_line}: header lacks {missing}; expected "
            "theta_i,phi_i,theta_o,phi_o and p or p_r,p_g,p_b (optional weight)"
        )
    if "p" in columns:
        p_columns = ["p"]
    elif all(c in columns for c in ("p_r", "p_g", "p_b")):
        p_columns = ["p_r", "p_g", "p_b"]
    else:
        raise MeasurementError(f"{path}:{header_line}: header needs a column p (or p_r, p_g, p_b)")
    unknown = set(columns) - set(_REQUIRED) - set(p_columns) - {"weight"}
    if unknown:
        raise MeasurementError(f"{path}:{header_line}: unknown columns {sorted(unknown)}")
    return columns, p_columns


def _csv_values(path: Path, chunk: list[tuple[int, str]], width: int) -> np.ndarray:
    """(rows, width) floats of a chunk of data lines; errors name the line."""
    commas = width - 1
    if all(line.count(",") == commas for _, line in chunk):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # numpy warns (and stops early) on a cell it cannot read
            try:
                flat = np.fromstring(",".join(line for _, line in chunk), sep=",")  # text mode: not deprecated
            except (ValueError, DeprecationWarning):
                flat = None
        if flat is not None and flat.size == len(chunk) * width:
            values = flat.reshape(len(chunk), width)
            finite = np.isfinite(values).all(axis=1)
            if finite.all():
                return values
            line_no, line = chunk[int(np.argmin(finite))]
            raise MeasurementError(f"{path}:{line_no}: NaN or infinite value in {line.strip()[:120]!r}")
    values = np.empty((len(chunk), width))  # the slow path finds the line numpy refused
    for r, (line_no, line) in enumerate(chunk):
        cells = line.split(",")
        if len(cells) != width:
            raise MeasurementError(f"{path}:{line_no}: {len(cells)} cells, the header has {width}")
        try:
            values[r] = [float(c) for c in cells]
        except ValueError:
            raise MeasurementError(f"{path}:{line_no}: not a number in {line.strip()[:120]!r}") from None
        if not np.isfinite(values[r]).all():
            raise MeasurementError(f"{path}:{line_no}: NaN or infinite value in {line.strip()[:120]!r}")
    return values


def _csv_chunk(path: Path, chunk, columns: list[str], p_columns: list[str], negative: str, parts: list) -> int:
    """Parse and check one chunk of data lines and append its (wi, wo, p, weight) to ``parts``;
    returns how many tuples had a negative p."""
    values = _csv_values(path, chunk, len(columns))
    for name, limit, what in _VALUE_LIMITS:
        if name in columns:
            over = np.abs(values[:, columns.index(name)]) > limit
            if over.any():
                line_no, line = chunk[int(np.argmax(over))]
                raise MeasurementError(f"{path}:{line_no}: {name} above {what} in {line.strip()[:120]!r}")
    col = {name: values[:, i] for i, name in enumerate(columns)}
    theta_i, theta_o = col["theta_i"], col["theta_o"]
    bad = (theta_i < 0) | (theta_i >= 90) | (theta_o < 0) | (theta_o > 180) | (np.abs(theta_o - 90) < 1e-9)
    if bad.any():
        line_no = chunk[int(np.argmax(bad))][0]
        raise MeasurementError(
            f"{path}:{line_no}: theta_i must lie in [0, 90) and theta_o in [0, 180] without 90 (above 90: transmission)"
        )
    p = np.stack([col[c] for c in p_columns], axis=1)
    keep = np.ones(len(chunk), dtype=bool)
    neg = (p < 0).any(axis=1)
    if neg.any():
        if negative == "error":
            line_no = chunk[int(np.argmax(neg))][0]
            raise MeasurementError(
                f"{path}:{line_no}: negative transfer probability (pass negative='clamp' "
                "or 'mask', CLI --negative, for background-subtracted data)"
            )
        if negative == "clamp":
            p = np.maximum(p, 0.0)
        else:
            keep = ~neg
    wi = spherical_direction(np.radians(theta_i[keep]), np.radians(col["phi_i"][keep]))
    wo = spherical_direction(np.radians(theta_o[keep]), np.radians(col["phi_o"][keep]))
    weight = col["weight"][keep] if "weight" in col else np.abs(np.sin(np.radians(theta_o[keep])))
    parts.append((wi, wo, p[keep], weight))
    return int(neg.sum())


def write_csv(measurement: Measurement, path, comment: str = "") -> None:
    """Write ``measurement`` in the format :func:`read_csv` reads (weights included)."""
    theta_i, phi_i = angles_deg(measurement.wi)
    theta_o, phi_o = angles_deg(measurement.wo)
    p_names = ["p"] if measurement.channels == 1 else ["p_r", "p_g", "p_b"]
    buf = io.StringIO()
    buf.write("# lobeview goniophotometer measurement: angles in degrees in the sample frame (z = normal,\n")
    buf.write("# x = tangent/brushing direction); theta_o > 90 = transmission; p = f_s |cos theta_o| [1/sr];\n")
    buf.write("# weight = solid angle the tuple represents (Eq. 3.7's w)\n")
    for line in comment.splitlines():
        buf.write(f"# {line}\n")
    buf.write(",".join(["theta_i", "phi_i", "theta_o", "phi_o", *p_names, "weight"]) + "\n")
    table = np.column_stack([theta_i, phi_i, theta_o, phi_o, measurement.p, measurement.weight])
    np.savetxt(buf, table, delimiter=",", fmt="%.9g")
    Path(path).write_text(buf.getvalue(), encoding="utf-8")


# -- MERL ------------------------------------------------------------------------------------------


def read_merl(path, limits: Limits | None = None) -> np.ndarray:
    """A MERL ``.binary`` file -> table of shape (90, 90, 180, 3) (theta_h, theta_d, phi_d, RGB)
    of BRDF values with the colour scale factors applied; unmeasured cells (negative in the
    file) are NaN. The file size must equal the layout's exactly."""
    path = Path(path)
    size = check_regular_file(path, "MERL BRDF", limits or Limits(max_file_bytes=MERL_FILE_BYTES))
    if size != MERL_FILE_BYTES:
        raise MeasurementError(f"{path}: {size} bytes; a MERL table of {MERL_DIMS} is exactly {MERL_FILE_BYTES} bytes")
    raw = path.read_bytes()
    dims = tuple(int(d) for d in np.frombuffer(raw, dtype="<i4", count=3))
    if dims != MERL_DIMS:
        raise MeasurementError(f"{path}: declared dimensions {dims}, expected {MERL_DIMS} (theta_h, theta_d, phi_d)")
    values = np.frombuffer(raw, dtype="<f8", offset=12).reshape(3, *MERL_DIMS)
    if not np.isfinite(values).all():
        index = np.unravel_index(int(np.argmax(~np.isfinite(values))), values.shape)
        raise MeasurementError(f"{path}: NaN or infinite value at (channel, theta_h, theta_d, phi_d) = {index}")
    table = np.moveaxis(values, 0, -1) * MERL_SCALE
    return np.where(values.transpose(1, 2, 3, 0) < 0, np.nan, table)


def write_merl(table: np.ndarray, path) -> None:
    """Write a (90, 90, 180, 3) BRDF table in MERL's layout (NaN cells written as -1)."""
    table = np.asarray(table, dtype=np.float64)
    if table.shape != (*MERL_DIMS, 3):
        raise MeasurementError(f"a MERL table has shape {(*MERL_DIMS, 3)}, got {table.shape}")
    raw = np.where(np.isnan(table), -1.0, table / MERL_SCALE)
    with open(path, "wb") as fh:
        fh.write(np.asarray(MERL_DIMS, dtype="<i4").tobytes())
        fh.write(np.ascontiguousarray(np.moveaxis(raw, -1, 0), dtype="<f8").tobytes())


def merl_cell_angles() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (theta_h, theta_d, phi_d) in radians at the centre of each MERL cell in index space
    (the index functions floor, so a cell's value stands for [i, i + 1)): theta_h =
    ((i + 1/2) / 90)^2 x 90 deg, theta_d = (i + 1/2) deg, phi_d = (i + 1/2) deg."""
    theta_h = ((np.arange(MERL_DIMS[0]) + 0.5) / MERL_DIMS[0]) ** 2 * (math.pi / 2)
    theta_d = (np.arange(MERL_DIMS[1]) + 0.5) / MERL_DIMS[1] * (math.pi / 2)
    phi_d = (np.arange(MERL_DIMS[2]) + 0.5) / MERL_DIMS[2] * math.pi
    return theta_h, theta_d, phi_d


def _rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation of vectors ``v`` about a unit ``axis`` by ``angle`` (radians)."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + axis * (v @ axis)[..., None] * (1.0 - c) + np.cross(axis, v) * s


def half_diff_to_directions(theta_h, theta_d, phi_d, phi_h=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Rusinkiewicz's half/difference angles -> (wi, wo); the inverse of
    :func:`directions_to_half_diff`."""
    theta_h, theta_d, phi_d, phi_h = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d, phi_h))
    )
    diff = spherical_direction(theta_d, phi_d)
    h = spherical_direction(theta_h, phi_h)
    wi = _rotate(_rotate(diff, np.array([0.0, 1.0, 0.0]), theta_h), np.array([0.0, 0.0, 1.0]), phi_h)
    wo = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
    return wi, wo


def directions_to_half_diff(wi: np.ndarray, wo: np.ndarray):
    """(wi, wo) -> (theta_h, phi_h, theta_d, phi_d) in radians, as MERL's
    std_coords_to_half_diff_coords: rotate wi by -phi_h about n, then by -theta_h about y."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    d = _rotate(wi, np.array([0.0, 0.0, 1.0]), -phi_h)
    d = _rotate(d, np.array([0.0, 1.0, 0.0]), -theta_h)
    theta_d = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    phi_d = np.arctan2(d[..., 1], d[..., 0])
    return theta_h, phi_h, theta_d, phi_d


def merl_indices(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MERL's lookup index functions (theta_half_index, theta_diff_index, phi_diff_index)."""
    theta_h, _, theta_d, phi_d = directions_to_half_diff(wi, wo)
    n_h, n_d, n_p = MERL_DIMS
    ih = np.sqrt(np.maximum(theta_h, 0.0) / (math.pi / 2) * n_h * n_h).astype(int)
    idd = (theta_d / (math.pi / 2) * n_d).astype(int)
    phi_d = np.where(phi_d < 0.0, phi_d + math.pi, phi_d)  # reciprocity: phi_d ~ phi_d + pi
    ip = (phi_d / math.pi * n_p).astype(int)
    return np.clip(ih, 0, n_h - 1), np.clip(idd, 0, n_d - 1), np.clip(ip, 0, n_p - 1)


def merl_lookup(table: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """BRDF values (N, 3) of a MERL table at direction pairs (nearest cell, as MERL's code)."""
    return table[merl_indices(wi, wo)]


def merl_table_from_bsdf(bsdf) -> np.ndarray:
    """Evaluate an isotropic lobeview BSDF at every MERL cell (cells whose directions fall below
    the horizon are NaN, as unmeasured)."""
    theta_h, theta_d, phi_d = merl_cell_angles()
    th, td, pd = np.meshgrid(theta_h, theta_d, phi_d, indexing="ij")
    wi, wo = half_diff_to_directions(th, td, pd)
    value = bsdf.eval(wi, wo)
    below = (wi[..., 2] <= 0.0) | (wo[..., 2] <= 0.0)
    return np.where(below[..., None], np.nan, value)


def merl_measurement(table: np.ndarray, stride: tuple[int, int, int] = (2, 3, 6), name: str = "merl") -> Measurement:
    """Tuples from every ``stride``-th MERL cell (theta_h, theta_d, phi_d) with both directions
    above the horizon and a measured value. Each tuple's weight is the 4D measure its cells
    represent, 4 cos(theta_d) sin(theta_h) sin(theta_d) dtheta_h dtheta_d dphi_d (the Jacobian
    of the half/difference parameterisation, dwi dwo = 4 cos theta_d dw_h dw_d), divided by the
    |cos theta_i| Eq. 3.7 multiplies by, so the metric weights every pair by its solid angles."""
    theta_h, theta_d, phi_d = merl_cell_angles()
    edges_h = (np.arange(MERL_DIMS[0] + 1) / MERL_DIMS[0]) ** 2 * (math.pi / 2)
    ih = np.arange(0, MERL_DIMS[0], stride[0])
    idd = np.arange(0, MERL_DIMS[1], stride[1])
    ip = np.arange(0, MERL_DIMS[2], stride[2])
    gh, gd, gp = np.meshgrid(ih, idd, ip, indexing="ij")
    th, td, pd = theta_h[gh], theta_d[gd], phi_d[gp]
    wi, wo = half_diff_to_directions(th, td, pd)
    f = table[gh, gd, gp]
    ok = (wi[..., 2] > 1e-6) & (wo[..., 2] > 1e-6) & np.isfinite(f).all(axis=-1)
    d_th = (edges_h[gh + 1] - edges_h[gh]) * stride[0]
    measure = 4.0 * np.cos(td) * np.sin(th) * np.sin(td) * d_th * (math.pi / 2 / MERL_DIMS[1] * stride[1])
    measure = measure * (math.pi / MERL_DIMS[2] * stride[2]) * 2.0  # phi_d over [0, pi) stands for [0, 2 pi)
    wi, wo, f = wi[ok], wo[ok], f[ok]
    p = f * wo[:, 2:3]
    if not len(wi):
        raise MeasurementError(f"{name}: no measured cell above the horizon at stride {stride}")
    return Measurement(
        wi,
        wo,
        p,
        measure[ok] / wi[:, 2],
        name=name,
        source="MERL table",
        notes=[f"MERL cells at stride {stride}: {len(wi)} tuples"],
    )


def merl_goniometer_measurement(
    table: np.ndarray,
    theta_i_deg=THESIS_ISOTROPIC_THETA_I_DEG,
    phi_i_deg=(0.0,),
    theta_step_deg: float = 2.5,
    phi_step_deg: float = 10.0,
    name: str = "merl",
) -> Measurement:
    """A MERL table read at a goniophotometer's directions (nearest cell, as MERL's lookup):
    tuples with incidences the slice plots can show. Unmeasured cells are dropped."""
    wi, wo, weight = goniometer_directions(theta_i_deg, phi_i_deg, theta_step_deg, phi_step_deg)
    f = merl_lookup(table, wi, wo)
    ok = np.isfinite(f).all(axis=1)
    return Measurement(wi[ok], wo[ok], f[ok] * wo[ok, 2:3], weight[ok], name=name, source="MERL table (goniometer)")


# -- virtual measurements --------------------------------------------------------------------------


def goniometer_directions(
    theta_i_deg,
    phi_i_deg,
    theta_step_deg: float = 5.0,
    phi_step_deg: float = 15.0,
    transmission: bool = False,
    peak_radius_deg: float = 12.0,
    peak_rings: int = 14,
    peak_azimuths: int = 24,
):
    """Direction pairs of a virtual goniophotometer, with each detector direction's solid angle.

    For every incidence (theta_i, phi_i): a uniform (theta_o, phi_o) grid over the reflection
    hemisphere (and the transmission hemisphere if ``transmission``), theta_o at cell centres and
    phi_o from 0 (so the plane of incidence is scanned), solid angle sin(theta_o) dtheta dphi;
    within ``peak_radius_deg`` of the mirror direction (and of the straight-through direction)
    the grid is replaced by a polar grid about it with rings spaced
    geometrically from 0.02 deg, so lobes far narrower than the grid (the thesis' Miro 5 has
    m = 0.007, a lobe of ~0.4 deg) are resolved, as a goniophotometer scanning the peak does. The
    union of both grids partitions the sphere, so the weights stay solid angles.
    """
    _check_grid_size(theta_i_deg, phi_i_deg, theta_step_deg, phi_step_deg, transmission, peak_rings * peak_azimuths)
    th_o = np.radians(np.arange(theta_step_deg / 2, 90.0, theta_step_deg))
    ph_o = np.radians(np.arange(0.0, 360.0, phi_step_deg))  # from 0: the plane of incidence is scanned
    grid_t, grid_p = np.meshgrid(th_o, ph_o, indexing="ij")
    grid = spherical_direction(grid_t, grid_p).reshape(-1, 3)
    grid_w = (np.sin(grid_t) * math.radians(theta_step_deg) * math.radians(phi_step_deg)).reshape(-1)
    radius = math.radians(peak_radius_deg)
    edges = np.concatenate([[0.0], np.geomspace(math.radians(0.02), radius, peak_rings)])
    ring_r = 0.5 * (edges[:-1] + edges[1:])
    ring_w = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2 * math.pi / peak_azimuths)
    az = np.arange(peak_azimuths) * 2 * math.pi / peak_azimuths
    rr, aa = np.meshgrid(ring_r, az, indexing="ij")
    local = spherical_direction(rr, aa).reshape(-1, 3)
    local_w = np.repeat(ring_w, peak_azimuths)
    wis, wos, ws = [], [], []
    for t in theta_i_deg:
        for ph in phi_i_deg:
            wi = spherical_direction(np.radians(t), np.radians(ph))
            mirror = np.array([-wi[0], -wi[1], wi[2]])
            for sign in (1.0, -1.0) if transmission else (1.0,):
                axis = mirror if sign > 0 else -wi
                hemi = grid * np.array([1.0, 1.0, sign])
                outside = np.arccos(np.clip(hemi @ axis, -1, 1)) > radius
                peak = _to_frame(local, axis)
                inside = peak[:, 2] * sign > 1e-4  # drop peak directions past the horizon
                wo = np.concatenate([hemi[outside], peak[inside]])
                wis.append(np.broadcast_to(wi, wo.shape))
                wos.append(wo)
                ws.append(np.concatenate([grid_w[outside], local_w[inside]]))
    return np.concatenate(wis), np.concatenate(wos), np.concatenate(ws)


def _check_grid_size(theta_i_deg, phi_i_deg, theta_step_deg, phi_step_deg, transmission, peak_directions) -> None:
    """Refuse a grid of more than MAX_VIRTUAL_TUPLES tuples (or non-finite steps) before any
    array is made: ``--theta-step 0.0001`` asked for 900 million tuples and was killed for memory."""
    for name, step in (("theta", theta_step_deg), ("phi", phi_step_deg)):
        if not (math.isfinite(step) and step > 0):
            raise MeasurementError(f"the {name} step must be a finite number of degrees > 0, got {step}")
    thetas = max(0, math.ceil((90.0 - theta_step_deg / 2) / theta_step_deg))
    phis = math.ceil(360.0 / phi_step_deg)
    incidences = len(theta_i_deg) * len(phi_i_deg) * (2 if transmission else 1)
    total = incidences * (thetas * phis + peak_directions)
    if total > MAX_VIRTUAL_TUPLES:
        raise MeasurementError(
            f"a detector grid of {thetas} x {phis} directions ({theta_step_deg:g} x {phi_step_deg:g} deg) at "
            f"{incidences} incidences makes {total:,} tuples, more than the limit of {MAX_VIRTUAL_TUPLES:,} "
            "(about 1.5 GB): use larger --theta-step/--phi-step or fewer incidences"
        )


def _to_frame(local: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotate directions given about +z so that +z maps to ``axis``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[2]) > 0.9 else np.array([0.0, 0.0, 1.0])
    t = np.cross(helper, axis)
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    return local[:, :1] * t + local[:, 1:2] * b + local[:, 2:3] * axis
