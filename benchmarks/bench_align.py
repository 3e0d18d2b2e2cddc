"""Aligning many columns that share one time array: on the grid, off it by plan, per column.

Run from the repository root:

    python benchmarks/bench_align.py                         # quick: 120 columns
    python benchmarks/bench_align.py --columns 1200 --repeat 3   # the goal's size
    python benchmarks/bench_align.py --engine 600 --repeat 3    # whole runs, as users run them

Side by side in one process, rounds interleaved so that a neighbour's load falls on all alike,
``--columns`` model columns of ``--samples`` samples (default an hour at 100 Hz) are put on the
reference's grid:

* on the grid: the columns are used as logged (the yardstick: 1.0×);
* off the grid (±0.2 step jitter), one interpolation plan applied by numpy;
* the same plan applied by the compiled kernel (with the ``fast`` extra);
* each column deferred and put on the grid into one buffer per thread, on two threads, as the
  engine scores off-grid columns (numpy, and the kernel);
* ``np.interp`` per column, the way before plans.

Every way must give np.interp's values bit for bit; the run stops if one does not.

``--engine N`` times whole runs instead: the spec of N signals × 1 h at 100 Hz from
``bench_scale.py``'s end-to-end data, scored with the defaults against the model file as
written (on the grid) and against the same file with its time stamps jittered by ±0.2 step
(every model column off the grid), each run in a fresh process, interleaved: wall and CPU time
from reading the spec to the result, and the process's peak memory.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from pytest_hevval.core import kernel
from pytest_hevval.data import kernel_cache
from pytest_hevval.data.align import align_records
from pytest_hevval.data.record import Channel, Record

RATE_HZ = 100.0


def _record(name: str, time_s: np.ndarray, columns: dict[str, np.ndarray]) -> Record:
    channels = {k: Channel(time=time_s, values=v) for k, v in columns.items()}
    return Record(source=name, channels=channels, available=tuple(columns))


def _fresh(record: Record) -> Record:
    """The same samples in new channels."""
    return _record(
        record.source,
        next(iter(record.channels.values())).time,
        {k: c.values for k, c in record.channels.items()},
    )


def _align_all(reference: Record, model: Record, names: list[str]) -> list[np.ndarray]:
    aligned = align_records(reference, model, reference_columns=["x"], model_columns=names)
    return [aligned.column("model", name, "linear") for name in names]


def _engine_specs(signals: int) -> tuple[Path, Path]:
    """The end-to-end spec on the grid, and one whose model file's time stamps are jittered."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_scale import e2e_data

    folder = e2e_data(signals, 3600.0, RATE_HZ)
    on_grid = folder / "parquet.hevval.yaml"
    off_grid = folder / "jittered.hevval.yaml"
    jittered = folder / "sim-jittered.parquet"
    if not jittered.exists():
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pq.read_table(folder / "sim.parquet")
        stamps = table.column("time").to_numpy()
        step = float(stamps[1] - stamps[0])
        moved = stamps + np.random.default_rng(1).uniform(-0.2, 0.2, stamps.size) * step
        table = table.set_column(table.column_names.index("time"), "time", pa.array(moved))
        pq.write_table(table, jittered)
    off_grid.write_text(on_grid.read_text().replace("path: sim.parquet", f"path: {jittered.name}"))
    return on_grid, off_grid


def _child(spec_path: str) -> None:
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import load_spec

    wall, cpu = time.perf_counter(), time.process_time()
    evaluate_spec(load_spec(spec_path))
    print(
        json.dumps(
            {
                "wall": time.perf_counter() - wall,
                "cpu": time.process_time() - cpu,
                "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            }
        )
    )


def _engine(signals: int, repeat: int) -> int:
    on_grid, off_grid = _engine_specs(signals)
    runs: dict[str, list[dict[str, float]]] = {"on the grid": [], "off the grid": []}
    for _ in range(repeat):
        for label, spec in (("on the grid", on_grid), ("off the grid", off_grid)):
            out = subprocess.run(
                [sys.executable, __file__, "--child", str(spec)],
                capture_output=True,
                text=True,
                check=True,
            )
            runs[label].append(json.loads(out.stdout.strip().splitlines()[-1]))
            found = runs[label][-1]
            print(
                f"  {label:12s} {found['wall']:6.2f} s wall {found['cpu']:6.2f} s CPU "
                f"{found['peak_mb']:7.0f} MB peak",
                flush=True,
            )
    print(
        f"{signals} signals × 1 h, model columns on and off the grid, {repeat} fresh processes "
        f"each; load average {os.getloadavg()[0]:.1f}; {kernel_cache.describe()}"
    )
    for key in ("wall", "cpu", "peak_mb"):
        on = [r[key] for r in runs["on the grid"]]
        off = [r[key] for r in runs["off the grid"]]
        ratios = [b / a for a, b in zip(on, off, strict=True)]
        print(
            f"  {key:8s} on {statistics.median(on):8.2f}  off {statistics.median(off):8.2f} "
            f"(medians)  off/on per round {min(ratios):.2f}–{max(ratios):.2f}"
        )
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--columns", type=int, default=120)
    parser.add_argument("--samples", type=int, default=360_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--engine", type=int, default=0, help="whole runs of this many signals")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child)
        return 0
    if args.engine:
        return _engine(args.engine, args.repeat)

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
            # New channels each time: a channel keeps what it learnt (whether it is finite),
            # and a run reads each file's channels afresh.
            return _align_all(reference, _fresh(record), names)

        return run

    ways: dict[str, Callable[[], list[np.ndarray]]] = {
        "on the grid, used as logged": with_path("numpy", on_grid),
        "off the grid, one plan, numpy": with_path("numpy", off_grid),
    }
    if kernel.active_path() == "numba":
        with_path("numba", off_grid)()  # compiled (or loaded from its cache) before timing
        ways["off the grid, one plan, kernel"] = with_path("numba", off_grid)

    def deferred(path: str) -> Callable[[], list[np.ndarray]]:
        """As the engine scores: each column put on the grid into its thread's one buffer."""

        def run() -> list[np.ndarray]:
            os.environ[kernel.KERNEL_ENV] = path
            aligned = align_records(
                reference, _fresh(off_grid), reference_columns=["x"], model_columns=names
            )
            buffers = threading.local()

            def one(name: str) -> None:
                if not hasattr(buffers, "out"):
                    buffers.out = np.empty(n)
                column = aligned.deferred_column("model", name, "linear")
                assert column is not None
                column.into(buffers.out)

            with ThreadPoolExecutor(max_workers=2) as pool:
                list(pool.map(one, names))
            return []

        return run

    check = align_records(reference, off_grid, reference_columns=["x"], model_columns=names)
    for name in names[:5]:
        column = check.deferred_column("model", name, "linear")
        assert column is not None
        if not np.array_equal(column.into(), np.interp(grid, jittered, columns[name])):
            sys.exit("deferred: values differ from np.interp")
    ways["off the grid, deferred into a buffer per thread, numpy"] = deferred("numpy")
    if kernel.active_path() == "numba":
        ways["off the grid, deferred into a buffer per thread, kernel"] = deferred("numba")
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
            if way.startswith("off") and got:
                for a, b in zip(got[:5], expected, strict=True):
                    if not np.array_equal(a, b):
                        sys.exit(f"{way}: values differ from np.interp")
            del got
    os.environ.pop(kernel.KERNEL_ENV, None)

    print(
        f"{args.columns} columns × {n:,} samples sharing one time array; best and median of "
        f"{args.repeat}; load average {os.getloadavg()[0]:.1f}; {kernel_cache.describe()}"
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
