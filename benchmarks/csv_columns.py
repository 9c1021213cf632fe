"""Benchmark row of the CSV reader on very wide files, run by :mod:`benchmarks.run`.

The reader was quadratic in the number of columns (10^4 columns 1.1 s, 3*10^4 7.9 s, 10^6 killed at 120 s); it
streams and looks each column up once now.  The row reads a 6-row file of 10^4 and of 10^5 columns, whole and by
a selection of every column in reverse order; the peer column is the 10^4-column read scaled linearly to 10^5
(a ratio of 1 or more says the reader is linear, its fixed costs included; a quadratic reader gives about 0.1)."""

from __future__ import annotations


def bench_csv_columns(quick, tmp, timed, row):
    """Seconds to read a wide CSV (whole, then every column selected by name) at 10^4 and 10^5 columns."""
    from pathlib import Path

    import numpy as np

    from interprim.datasets import load_demonstrations

    print("CSV reader, wide files")
    times = {}
    for n in (10_000, 100_000):
        path = Path(tmp) / f"wide{n}.csv"
        vals = np.round(np.random.default_rng(0).normal(size=(6, n)), 3)
        with open(path, "w") as fh:
            fh.write("time," + ",".join(f"c{i}" for i in range(n)) + "\n")
            for r in range(6):
                fh.write(f"{0.01 * r}," + ",".join(map(repr, vals[r].tolist())) + "\n")
        names = [f"c{i}" for i in range(n - 1, -1, -1)]
        times[n] = timed(lambda: (load_demonstrations(path), load_demonstrations(path, columns=names)),
                         n=1 if quick else 3, warm=0)
    row("CSV reader: 6 rows, whole + every column by name", "10^5 columns", times[100_000],
        "the same reader at 10^4 columns x 10", times[10_000] * 10,
        note="linear in columns when the ratio is >= 1 (quadratic: ~0.1; the old reader took minutes at 10^5)")
