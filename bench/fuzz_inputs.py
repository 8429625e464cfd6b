"""The fuzzer's inputs beside glTF and HDR images (issue 43 item 6, bench/fuzz.py): the sources it
writes for them and the CSV-specific mutation."""

from __future__ import annotations

import json
from pathlib import Path


def measurement_sources(folder: Path) -> None:
    """The inputs beside glTF (issue 43 item 6): a goniophotometer CSV (a coarse virtual
    measurement, ~200 rows), a measured material naming a MERL table by file (a short stand-in:
    a real table is 35 MB per case; its path and size checks are what is fuzzed), a camera path
    and a viewer script."""
    from lobeview.materials.measurement import write_csv
    from lobeview.materials.presets import PRESETS
    from lobeview.materials.virtual import virtual_measurement

    m = virtual_measurement(PRESETS["plastic"], theta_i_deg=(0, 30, 60), phi_i_deg=(0,), theta_step_deg=15.0,
                            phi_step_deg=45.0)  # fmt: skip
    write_csv(m, folder / "measurement.csv", comment="fuzz source: virtual plastic")
    (folder / "table.binary").write_bytes(b"\x5a\x00\x00\x00" * 64)
    (folder / "measured.json").write_text(json.dumps({"model": "measured", "file": "table.binary"}))
    keys = [{"t": float(t), "position": [float(t), 1.5, 4.0], "target": [0.0, 1.0, 0.0]} for t in range(3)]
    (folder / "path.json").write_text(json.dumps({"fov_y": 55.0, "keys": keys}, indent=1))
    steps = [{"frame": 2, "action": "method", "value": "lobe-7"}, {"frame": 4, "action": "quit"}]
    (folder / "script.json").write_text(json.dumps(steps, indent=1))


#: values a goniophotometer CSV cell is replaced by (the reader refuses or masks each, by line)
HOSTILE_CELLS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "-0", "", "abc", "9" * 400, "0x10", "1,2"]


def mutate_csv(path: Path, rng) -> str:
    """A structured edit of the CSV: a hostile cell, a duplicated or dropped column, a short or
    long row, a huge weight, a BOM, or a header at the end."""
    lines = path.read_text().splitlines()
    data = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
    header, rows = data[0], data[1:]
    kind = ["cell", "cell", "duplicate", "drop", "short", "long", "weight", "bom", "header"][int(rng.integers(9))]
    row = rows[int(rng.integers(len(rows)))]
    cells = lines[row].split(",")
    column = int(rng.integers(len(cells)))
    if kind == "cell":
        cells[column] = HOSTILE_CELLS[int(rng.integers(len(HOSTILE_CELLS)))]
        lines[row] = ",".join(cells)
    elif kind in ("duplicate", "drop"):
        for i in [header, *rows]:
            parts = lines[i].split(",")
            parts = parts + [parts[column]] if kind == "duplicate" else parts[:column] + parts[column + 1 :]
            lines[i] = ",".join(parts)
    elif kind == "short":
        lines[row] = ",".join(cells[:-1])
    elif kind == "long":
        lines[row] = ",".join([*cells, "1"])
    elif kind == "weight":
        lines[header] += ",weight"
        for i in rows:
            lines[i] += ",1e300" if i == row else ",0.01"
    elif kind == "bom":
        lines[0] = "\ufeff" + lines[0]
    else:
        lines.append(lines[header])
    path.write_text("\n".join(lines) + "\n")
    return f"csv {kind} at line {row + 1}, column {column}"
