"""Aligning many columns that share one time array: on the grid, off it by plan, per column.

Run from the repository root:

    python benchmarks/bench_align.py                         # quick: 120 columns
    python benchmarks/bench_align.py --columns 1200 --repeat 3   # the goal's size

Side by side in one process, rounds interleaved so that a neighbour's load falls on all alike,
``--columns`` model columns of ``--samples`` samples (default an hour at 100 Hz) are put on the
reference's grid:

* on the grid: the columns are used as logged (the yardstick: 1.0×);
* off the grid (±0.2 step jitter), one interpolation plan applied by numpy;
* the same plan applied by the compiled kernel (with the ``fast`` extra);
* ``np.interp`` per column, the way before plans.

Every way must give np.interp's values bit for bit; the run stops if one does not.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from pytest_hevval.core import kernel
from pytest_hevval.data.align import align_records
from pytest_hevval.data.record import Channel, Record

RATE_HZ = 100.0


def _record(name: str, time_s: np.ndarray, columns: dict[str, np.ndarray]) -> Record:
    channels = {k: Channel(time=time_s, values=v) for k, v in columns.items()}
    return Record(source=name, channels=channels, available=tuple(columns))


def _align_all(reference: Record, model: Record, names: list[str]) -> list[np.ndarray]:
    aligned = align_records(reference, model, reference_columns=["x"], model_columns=names)
    return [aligned.column("model", name, "linear") for name in names]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--columns", type=int, default=120)
    parser.add_argument("--samples", type=int, default=360_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    rng = np.random.default_rng(7)
    n = args.samples
    grid_time = np.arange(n) / RATE_HZ
    jittered = grid_time + rng.uniform(-0.2, 0.2, n) / RATE_HZ
    names = [f"c{i:04d}" for i in range(args.columns)]
    columns = {name: np.cumsum(rng.normal(size=n)) for name in names}
    reference = _record("ref", grid_time, {"x": np.zeros(n)})
    on_grid = _record("on-grid", grid_time, columns)
    off_grid = _record("off-grid", jittered, columns)
    grid = align_records(reference, off_grid, reference_columns=["x"], model_columns=names).time

    def with_path(path: str, record: Record) -> Callable[[], list[np.ndarray]]:
        def run() -> list[np.ndarray]:
            os.environ[kernel.KERNEL_ENV] = path
            return _align_all(reference, record, names)

        return run

    ways: dict[str, Callable[[], list[np.ndarray]]] = {
        "on the grid, used as logged": with_path("numpy", on_grid),
        "off the grid, one plan, numpy": with_path("numpy", off_grid),
    }
    if kernel.active_path() == "numba":
        with_path("numba", off_grid)()  # compiled (or loaded from its cache) before timing
        ways["off the grid, one plan, kernel"] = with_path("numba", off_grid)
    ways["off the grid, np.interp per column"] = lambda: [
        np.interp(grid, jittered, columns[name]) for name in names
    ]

    expected = [np.interp(grid, jittered, columns[name]) for name in names[:5]]
    times: dict[str, list[float]] = {way: [] for way in ways}
    for _ in range(args.repeat):
        for way, run in ways.items():
            started = time.perf_counter()
            got = run()
            times[way].append(time.perf_counter() - started)
            if way.startswith("off"):
                for a, b in zip(got[:5], expected, strict=True):
                    if not np.array_equal(a, b):
                        sys.exit(f"{way}: values differ from np.interp")
            del got
    os.environ.pop(kernel.KERNEL_ENV, None)

    print(
        f"{args.columns} columns × {n:,} samples sharing one time array; best and median of "
        f"{args.repeat}; load average {os.getloadavg()[0]:.1f}; {kernel.describe()}"
    )
    floor = min(times["on the grid, used as logged"])
    for way, seconds in times.items():
        print(
            f"  {way:36s} best {min(seconds):7.3f} s   median {statistics.median(seconds):7.3f} s"
            f"   {min(seconds) / floor:6.1f}× on grid"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
