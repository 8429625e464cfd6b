"""Fit lobe-N's reads to the lobe over alpha and view (materials/fitted_pattern.py) and write the
tables the estimator reads (materials/fitted_patterns.npz), with a summary of how close each
node's kernel came to its lobe.

    .venv/bin/python -m lobeview.bench.fitted_patterns            # lobe-7: Beckmann 7 reads, GGX 11 (about 15 min here)
    .venv/bin/python -m lobeview.bench.fitted_patterns --n 7 15   # more sample counts, added to the file
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from lobeview.bench.report import stamped_report_path
from lobeview.materials import fitted_pattern as fp

KINDS = ("beckmann", "ggx")


def summary(tables: list[fp.PatternTable], stamp: str, command: str, seconds: float) -> str:
    views = np.asarray(fp.TABLE_VIEWS_DEG)
    up_to_80 = views <= 80.0
    lines = [f"# Fitted lobe patterns ({stamp})", "", f"`{command}` ({seconds / 60:.1f} min on this machine)", "",
             "Relative L2 distance between the fitted reads' kernel and the lobe's f cos / albedo, per alpha: the "
             "worst node up to 80 degrees from the normal, and at the table's last view (89 degrees).", "",
             "| distribution | reads | " + " | ".join(f"{a:g}" for a in fp.TABLE_ALPHAS) + " |",
             "|---|---|" + "---|" * len(fp.TABLE_ALPHAS)]  # fmt: skip
    for table in tables:
        cells = [f"{row[up_to_80].max():.3f} / {row[-1]:.2f}" for row in table.distance]
        lines.append(f"| {table.kind} | {table.reads.shape[2]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[7], help="lobe-N sample counts (default 7)")
    parser.add_argument("--table", default=str(fp.TABLE_PATH), help="the tables' file (added to when it exists)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    counts = [(kind, fp.read_count(kind, n)) for n in args.n for kind in KINDS]
    for kind, reads in counts:
        if reads not in fp.TOPOLOGIES:
            raise SystemExit(f"no fitted topology for lobe-N with {reads} reads ({kind}); "
                             f"read counts with one: {sorted(fp.TOPOLOGIES)}")  # fmt: skip
    path = Path(args.table)
    tables = {}
    if path.exists():  # keep the tables of other counts
        with np.load(path, allow_pickle=False) as data:
            for key in data.files:
                if key.endswith("_reads"):
                    kind, reads = key[: -len("_reads")].rsplit("_", 1)
                    tables[(kind, int(reads))] = fp.load_table(kind, int(reads), path)
    start = time.perf_counter()
    for kind, reads in counts:
        tables[(kind, reads)] = fp.build_table(kind, reads, progress=print)
    seconds = time.perf_counter() - start
    fp.save_tables(list(tables.values()), path)
    fp.load_table.cache_clear()
    fp.fitted_sample_counts.cache_clear()
    report, stamp, command = stamped_report_path(args.out, "fitted-patterns", "fitted_patterns", argv)
    report.write_text(summary([tables[c] for c in counts], stamp, command, seconds))
    print(f"[fitted patterns] wrote {path} and {report}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
