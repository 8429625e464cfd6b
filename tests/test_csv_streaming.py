"""The goniophotometer CSV is read in chunks (issue 43 item 3: a 20 M row file within the limits
reached 7.7 GB when the whole text and a list of its lines were held first): the memory is the
kept tuples' arrays plus one chunk, the values are numpy's exact parse, and every error still
names its line, in any chunk."""

from __future__ import annotations

import re
import tracemalloc

import numpy as np
import pytest

from lobeview.materials import measurement as meas

HEADER = "# a comment\ntheta_i,phi_i,theta_o,phi_o,p_r,p_g,p_b\n"


def _rows(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [rng.uniform(0, 89, n), rng.uniform(0, 360, n), rng.uniform(0, 89, n), rng.uniform(0, 360, n),
         rng.uniform(0, 5, (n, 3))]
    )  # fmt: skip


def _write(path, rows: np.ndarray, extra: str = "") -> None:
    with open(path, "w") as handle:
        handle.write(HEADER)
        np.savetxt(handle, rows, delimiter=",", fmt="%.17g")
        handle.write(extra)


def test_values_are_exact_across_chunks(tmp_path, monkeypatch):
    """Chunks of 7 rows (blank and comment lines between) give the values a line-by-line float()
    parse gives, bit for bit."""
    monkeypatch.setattr(meas, "CSV_CHUNK_ROWS", 7)
    rows = _rows(50)
    path = tmp_path / "m.csv"
    _write(path, rows, extra="\n# trailing comment\n")
    m = meas.read_csv(path)
    assert len(m) == 50
    np.testing.assert_array_equal(m.p, rows[:, 4:])
    want = meas.spherical_direction(np.radians(rows[:, 2]), np.radians(rows[:, 3]))
    np.testing.assert_array_equal(m.wo, want)


@pytest.mark.parametrize(
    "bad_line, message",
    [
        ("1,2,3,4,5,6\n", "6 cells, the header has 7"),
        ("1,2,3,4,5,6,7,8\n", "8 cells, the header has 7"),
        ("1,2,3,4,0.5,abc,1\n", "not a number"),
        ("1,2,3,4,0.5,nan,1\n", "NaN or infinite"),
        ("1,2,3,4,0.5,,1\n", "not a number"),
        ("95,2,3,4,0.5,1,1\n", "theta_i must lie in [0, 90)"),
    ],
)
def test_errors_name_the_line_in_a_later_chunk(tmp_path, monkeypatch, bad_line, message):
    """A bad line in the third chunk is named by its line number; a short line next to a long one
    (the cell counts compensate over the chunk) is caught too."""
    monkeypatch.setattr(meas, "CSV_CHUNK_ROWS", 4)
    path = tmp_path / "bad.csv"
    good = "10,0,20,180,0.1,0.2,0.3\n"
    compensating = "10,0,20,180,0.1,0.2,0.3,9\n" if bad_line.count(",") == 5 else good
    body = HEADER + good * 9 + bad_line + compensating + good * 3  # the bad line is line 12
    path.write_text(body)
    with pytest.raises(meas.MeasurementError, match=":12: .*" + re.escape(message)):
        meas.read_csv(path)


def test_memory_is_the_kept_arrays_plus_one_chunk(tmp_path):
    """300 000 rows: the peak of the read is under 2.5x the measurement's own arrays (the whole
    text, its lines and a table of every value took more than 5x)."""
    rows = _rows(300_000, seed=1)
    path = tmp_path / "big.csv"
    _write(path, rows)
    tracemalloc.start()
    try:
        m = meas.read_csv(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = m.wi.nbytes + m.wo.nbytes + m.p.nbytes + m.weight.nbytes
    assert len(m) == 300_000
    assert peak < 2.5 * kept, f"peak {peak / 2**20:.1f} MiB for {kept / 2**20:.1f} MiB of arrays"
