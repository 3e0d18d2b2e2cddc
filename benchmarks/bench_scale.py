"""Scale benchmarks: one huge spec, many small specs on Dask, and other tools side by side.

Run from the project root::

    python benchmarks/bench_scale.py --quick          # a few minutes, small sizes
    python benchmarks/bench_scale.py --full           # the targets (needs ~8 GB disk, ~10 GB RAM)
    python benchmarks/bench_scale.py --full --only e2e,compare

Four parts, each printed with the sizes it ran at:

``e2e``
    One spec of 600 signals over 1 h at 100 Hz (360,000 samples × 600 channels × 2 sides),
    from Parquet and from MF4, each timed in a fresh process as ``hevval run`` would evaluate
    it: wall and CPU time (read + score), peak RSS (``VmHWM``) against the bytes of the loaded
    column values, and how often each data file was read (``DataCache.reads``, must be 1).
    Beside it, alternating, the yardstick in a fresh process: the used columns read with the
    format's own library (pyarrow, asammdf) plus ``signal_characteristics`` per pair on two
    threads. Targets: end to end ≤ 1.1 × that read + core and ≤ 8 s for Parquet on two cores,
    peak RSS ≤ 1.3 × the loaded column values. The files are read once before the runs so
    that they start from a warm page cache; that read is timed and printed.
``quality``
    The data-quality checks (:func:`pytest_hevval.data.quality.assess`) of the e2e reference's
    channels alone, read from Parquet, on one and on two threads.
``dask``
    100 specs of 10 min at 10 Hz with 20 signals each: serial in one process against
    :func:`pytest_hevval.scoring.cluster.evaluate_on_dask` on a ``LocalCluster`` of 2 worker
    processes; cluster start-up is timed apart from the run.
``compare``
    One signal pair scored by this package's ``signal_characteristics``, by ISO/TS 18571 as the
    ``objective-rating-metrics`` package implements it, and compared by pytest-regressions'
    ``num_regression`` comparison step (its ``_check_fn``: read both CSV files, ``isclose``).

Data files are generated once into ``benchmarks/.data/`` (not tracked) and reused.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE / ".data"


# ------------------------------------------------------------------------------------------
# Synthetic data


def _column(index: int, n: int, rate_hz: float, *, model: bool) -> np.ndarray:
    """One channel: a few slow oscillations plus a random walk; the model lags and is noisy.

    Each channel has its own seed, so one side can be generated without the other in memory.
    """
    rng = np.random.default_rng(index)
    t = np.arange(n) / rate_hz
    freqs = rng.uniform(0.002, 0.2, 3)
    phases = rng.uniform(0, 2 * np.pi, 3)
    ref = sum(np.sin(2 * np.pi * f * t + p) for f, p in zip(freqs, phases, strict=True))
    ref = 10.0 * ref + np.cumsum(rng.normal(0.0, 0.05, n))
    if not model:
        return ref
    noise = np.random.default_rng(100_000 + index)
    lag = int(noise.integers(0, max(2, int(0.5 * rate_hz))))
    return np.roll(ref, lag) * 1.01 + 0.1 + noise.normal(0.0, 0.2, n)


def _tree_spec(name: str, reference: str, model: str, columns: list[str], extra: str) -> str:
    """Sets of one parent and five children, every node scoring its own column."""
    lines = [f"name: {name}", f"reference: {reference}", f"model: {model}", extra, "sets:"]
    for start in range(0, len(columns), 6):
        group = columns[start : start + 6]
        lines.append(f"  - signal: {group[0]}")
        if len(group) > 1:
            lines.append("    children:")
            lines.extend(f"      - {{signal: {c}}}" for c in group[1:])
    return "\n".join(lines) + "\n"


def _write_side(folder: Path, side: str, columns: list[str], n: int, rate_hz: float) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    time_s = np.arange(n) / rate_hz
    arrays = {c: _column(i, n, rate_hz, model=side == "sim") for i, c in enumerate(columns)}
    table = pa.table({"time": time_s, **arrays})
    pq.write_table(table, folder / f"{side}.parquet")
    del table
    from asammdf import MDF, Signal

    with MDF(version="4.10") as mdf:
        mdf.append([Signal(v, time_s, name=c) for c, v in arrays.items()], common_timebase=True)
        mdf.save(str(folder / f"{side}.mf4"), overwrite=True)


def e2e_data(signals: int, duration_s: float, rate_hz: float) -> Path:
    """Reference and model files (Parquet and MF4) and one spec per format; made once."""
    n = int(duration_s * rate_hz)
    folder = DATA / f"e2e-{signals}x{n}"
    done = folder / ".complete"
    if done.exists():
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    columns = [f"c{i:03d}" for i in range(signals)]
    started = time.perf_counter()
    for side in ("ref", "sim"):
        _write_side(folder, side, columns, n, rate_hz)
    extra = "alignment: {max_lag_s: 5}\nthresholds: {mae: 0.5}"
    for fmt, options in (("parquet", ", time: time"), ("mf4", "")):
        text = _tree_spec(
            f"scale-{fmt}",
            f"{{path: ref.{fmt}{options}}}",
            f"{{path: sim.{fmt}{options}}}",
            columns,
            extra,
        )
        (folder / f"{fmt}.hevval.yaml").write_text(text)
    done.write_text("")
    print(
        f"  (generated {folder.relative_to(HERE.parent)} in {time.perf_counter() - started:.0f} s)"
    )
    return folder


def many_specs_data(count: int, signals: int, duration_s: float, rate_hz: float) -> list[Path]:
    """``count`` specs, each with its own reference and model Parquet files."""
    import pandas as pd

    n = int(duration_s * rate_hz)
    folder = DATA / f"many-{count}x{signals}x{n}"
    specs = [folder / f"spec{k:03d}.hevval.yaml" for k in range(count)]
    if (folder / ".complete").exists():
        return specs
    folder.mkdir(parents=True, exist_ok=True)
    columns = [f"c{i:03d}" for i in range(signals)]
    time_s = np.arange(n) / rate_hz
    for k, spec in enumerate(specs):
        for side in ("ref", "sim"):
            frame = pd.DataFrame(
                {
                    "time": time_s,
                    **{
                        c: _column(1000 * k + i, n, rate_hz, model=side == "sim")
                        for i, c in enumerate(columns)
                    },
                }
            )
            frame.to_parquet(folder / f"{side}{k:03d}.parquet", index=False)
        spec.write_text(
            _tree_spec(
                f"spec{k:03d}",
                f"{{path: ref{k:03d}.parquet, time: time}}",
                f"{{path: sim{k:03d}.parquet, time: time}}",
                columns,
                "alignment: {max_lag_s: 5}\nthresholds: {mae: 0.5}",
            )
        )
    (folder / ".complete").write_text("")
    return specs


# ------------------------------------------------------------------------------------------
# Part 1: one huge spec, in a fresh process


def _rss_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


def child_e2e(spec_path: str, intervals: bool = True) -> None:
    """Evaluate one spec as ``hevval run`` does; print measurements as JSON.

    ``intervals``: False as ``--hevval-no-intervals`` (no bootstrap intervals)."""
    from pytest_hevval.scoring.engine import DataCache, evaluate_spec
    from pytest_hevval.spec.load import load_spec

    baseline = _rss_kib("VmRSS")
    started = time.perf_counter()
    spec = load_spec(spec_path)
    cache = DataCache()
    cache.declare_spec(spec)
    # Reading first through the same cache splits the wall time without reading twice:
    # evaluate_spec then finds every column it needs already there.
    reference = cache.read(spec.reference, spec.reference_columns())
    model = cache.read(spec.model, spec.model_columns())
    read_done = time.perf_counter()
    evaluation = evaluate_spec(
        spec, cache=cache, rootdir=Path(spec_path).parent, intervals=intervals
    )
    finished = time.perf_counter()
    arrays: dict[int, int] = {}
    for record in (reference, model):
        for channel in record.channels.values():
            arrays[id(channel.values)] = channel.values.nbytes
            arrays[id(channel.time)] = channel.time.nbytes
    values_bytes = sum(c.values.nbytes for r in (reference, model) for c in r.channels.values())
    result = evaluation.result
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(
        json.dumps(
            {
                "cpu_s": usage.ru_utime + usage.ru_stime,
                "sys_s": usage.ru_stime,
                "load": os.getloadavg()[0],
                "signals": len(result.signals),
                "samples": result.alignment.n_samples,
                "phi": result.phi,
                "read_s": read_done - started,
                "score_s": finished - read_done,
                "wall_s": finished - started,
                "baseline_mib": baseline / 1024,
                "hwm_mib": _rss_kib("VmHWM") / 1024,
                "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                "values_mib": values_bytes / 2**20,
                "loaded_mib": sum(arrays.values()) / 2**20,
                "reads": {Path(k).name: v for k, v in cache.reads.items()},
            }
        )
    )


def child_floor(spec_path: str) -> None:
    """The budget's yardstick: read the used columns with the format's own library, then
    score the pairs with the core on two threads; print measurements as JSON."""
    from pytest_hevval.core.characteristics import signal_characteristics
    from pytest_hevval.spec.load import load_spec

    started = time.perf_counter()
    spec = load_spec(spec_path)
    folder = Path(spec_path).parent
    columns = sorted(spec.reference_columns())
    fmt = Path(str(spec.reference.path)).suffix
    sides = []
    for side in ("ref", "sim"):
        path = folder / f"{side}{fmt}"
        if fmt == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(path, columns=["time", *columns])
            time_s = table.column("time").to_numpy()
            values = {c: table.column(c).to_numpy() for c in columns}
            del table
        else:
            from asammdf import MDF

            with MDF(str(path)) as mdf:
                signals = mdf.select(columns)
            time_s = signals[0].timestamps
            values = {c: s.samples for c, s in zip(columns, signals, strict=True)}
        sides.append((time_s, values))
    read_done = time.perf_counter()
    dt = float(sides[0][0][1] - sides[0][0][0])

    def score(name: str) -> object:
        return signal_characteristics(
            sides[0][1][name], sides[1][1][name], dt=dt, max_lag_s=5, workers=1
        )

    # Two pairs at a time, one thread each: the fastest use of two cores for many pairs
    # (a pair of 360,000 samples is too short to share between threads).
    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(score, columns))
    finished = time.perf_counter()
    print(
        json.dumps(
            {
                "read_s": read_done - started,
                "core_s": finished - read_done,
                "wall_s": finished - started,
                "cpu_s": sum(resource.getrusage(resource.RUSAGE_SELF)[:2]),
                "hwm_mib": _rss_kib("VmHWM") / 1024,
            }
        )
    )


def _timed_child(*arguments: str) -> tuple[float, dict[str, float]]:
    """(process wall time from start to exit, the child's JSON line)."""
    started = time.perf_counter()
    output = subprocess.run(
        [sys.executable, __file__, *arguments], check=True, capture_output=True, text=True
    ).stdout
    return time.perf_counter() - started, json.loads(output.strip().splitlines()[-1])


def _read_through(path: Path) -> None:
    with path.open("rb") as handle:
        while handle.read(1 << 24):
            pass


def part_e2e(
    signals: int,
    duration_s: float,
    rate_hz: float,
    formats: tuple[str, ...] = ("parquet", "mf4"),
    intervals: bool = True,
) -> None:
    folder = e2e_data(signals, duration_s, rate_hz)
    n = int(duration_s * rate_hz)
    print(
        f"\n== e2e: one spec, {signals} signals × {n:,} samples × 2 sides"
        f"{'' if intervals else ', without bootstrap intervals'} =="
    )
    for fmt in formats:
        spec = folder / f"{fmt}.hevval.yaml"
        paths = [folder / f"{side}.{fmt}" for side in ("ref", "sim")]
        files = sum(p.stat().st_size for p in paths)
        # Timed apart: what a cold page cache adds; the run below then reads from memory.
        started = time.perf_counter()
        for path in paths:
            _read_through(path)
        raw_read = time.perf_counter() - started
        # The run and its yardstick alternate, each in a fresh process, best of two each.
        runs = []
        floors = []
        for _ in range(2):
            runs.append(
                _timed_child("--child-e2e", str(spec), *([] if intervals else ["--no-intervals"]))
            )
            floors.append(_timed_child("--child-floor", str(spec)))
        process_s, m = min(runs, key=lambda r: r[0])
        floor_process_s, f = min(floors, key=lambda r: r[0])
        yardstick = f["read_s"] + f["core_s"]
        reads_ok = all(v == 1 for v in m["reads"].values()) and len(m["reads"]) == 2
        print(
            f"{fmt}: {files / 2**30:.2f} GiB of files (sequential read {raw_read:.1f} s, "
            f"not included below)\n"
            f"  wall {m['wall_s']:.1f} s = read {m['read_s']:.1f} s + score {m['score_s']:.1f} s; "
            f"CPU {m['cpu_s']:.1f} s (system {m['sys_s']:.1f} s); load average {m['load']:.1f}\n"
            f"  peak RSS {m['hwm_mib'] / 1024:.2f} GiB = {m['hwm_mib'] / m['values_mib']:.2f} × "
            f"the loaded column values ({m['values_mib'] / 1024:.2f} GiB); "
            f"{m['hwm_mib'] / m['loaded_mib']:.2f} × all arrays the readers returned "
            f"({m['loaded_mib'] / 1024:.2f} GiB with the time arrays); "
            f"RSS after imports {m['baseline_mib']:.0f} MiB\n"
            f"  reads {m['reads']}: {'each file once' if reads_ok else 'FAIL: not once each'}\n"
            f"  end to end {process_s:.1f} s (process start to exit; {m['wall_s']:.1f} s after "
            f"imports) against read the used columns + core {yardstick:.1f} s "
            f"(read {f['read_s']:.1f} s + core {f['core_s']:.1f} s, "
            f"process {floor_process_s:.1f} s):"
            f" {m['wall_s'] / yardstick:.2f}× after imports, {process_s / floor_process_s:.2f}× "
            f"process to process; CPU {m['cpu_s']:.1f} s against {f['cpu_s']:.1f} s; "
            f"yardstick peak RSS {f['hwm_mib'] / 1024:.2f} GiB\n"
            f"  against this run's own read + the yardstick's core "
            f"{m['read_s'] + f['core_s']:.1f} s: {m['wall_s'] / (m['read_s'] + f['core_s']):.2f}×"
        )


def part_quality(signals: int, duration_s: float, rate_hz: float, repeat: int = 3) -> None:
    """The data-quality checks of the e2e reference alone, on one and on two threads, on the
    numpy path and the compiled one, interleaved: as logged, and rounded to 0.1 (a logger's
    resolution: flat steps, so flat lines and saturation are looked for too)."""
    from pytest_hevval.core import kernel
    from pytest_hevval.data.quality import QualityLimits, assess
    from pytest_hevval.data.readers import read_record
    from pytest_hevval.data.record import Channel, Record, SourceOptions
    from pytest_hevval.scoring.allocator import tune_allocator

    folder = e2e_data(signals, duration_s, rate_hz)
    n = int(duration_s * rate_hz)
    tune_allocator()  # as evaluate_spec does: column-sized temporaries stay in the heap
    columns = [f"c{i:03d}" for i in range(signals)]
    logged = read_record(str(folder / "ref.parquet"), columns, SourceOptions(time="time"))
    rounded = {
        name: (channel.time, np.round(np.asarray(channel.values), 1))
        for name, channel in logged.channels.items()
    }
    records = {
        "as logged": {name: (c.time, c.values) for name, c in logged.channels.items()},
        "rounded to 0.1": rounded,
    }
    paths = ["numpy", "numba"] if kernel.requested_path() != "numpy" else ["numpy"]
    if "numba" in paths:
        kernel.load_or_raise()  # its load is a run's cost once, not the checks'
    print(f"\n== quality: data-quality checks of {signals} reference channels × {n:,} samples ==")
    saved = os.environ.get(kernel.KERNEL_ENV)
    try:
        for _ in range(repeat):
            for label, arrays in records.items():
                for path in paths:
                    os.environ[kernel.KERNEL_ENV] = path
                    for threads in (1, 2):
                        # Fresh channels: whether a column is finite is found once per channel.
                        record = Record(
                            source=logged.source,
                            channels={k: Channel(t, v) for k, (t, v) in arrays.items()},
                        )
                        cpu = time.process_time()
                        started = time.perf_counter()
                        found = assess(record, columns, QualityLimits(), threads=threads)
                        wall = time.perf_counter() - started
                        print(
                            f"  {label}, {path}, {threads} thread(s): wall {wall:.3f} s, "
                            f"CPU {time.process_time() - cpu:.3f} s, {len(found)} findings; "
                            f"load average {os.getloadavg()[0]:.1f}"
                        )
    finally:
        if saved is None:
            os.environ.pop(kernel.KERNEL_ENV, None)
        else:
            os.environ[kernel.KERNEL_ENV] = saved


# ------------------------------------------------------------------------------------------
# Part 2: many specs, serial against Dask


@contextmanager
def _timer(into: dict[str, float], key: str) -> Iterator[None]:
    started = time.perf_counter()
    yield
    into[key] = time.perf_counter() - started


def part_dask(count: int, signals: int, duration_s: float, rate_hz: float) -> None:
    from pytest_hevval.scoring.cluster import evaluate_on_dask
    from pytest_hevval.scoring.engine import DataCache, evaluate_spec
    from pytest_hevval.spec.load import load_spec

    specs = many_specs_data(count, signals, duration_s, rate_hz)
    n = int(duration_s * rate_hz)
    print(f"\n== dask: {count} specs × {signals} signals × {n:,} samples ==")
    times: dict[str, float] = {}
    # Imports and first-call costs are paid before timing, here as on the Dask workers below.
    for path in specs[:4]:
        evaluate_spec(load_spec(path), rootdir=path.parent)
    with _timer(times, "serial"):
        cache = DataCache()
        loaded = [load_spec(p) for p in specs]
        for spec in loaded:
            cache.declare_spec(spec)
        serial = [
            evaluate_spec(s, cache=cache, rootdir=specs[0].parent).result.to_dict() for s in loaded
        ]

    import distributed

    with _timer(times, "start"):
        cluster = distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        )
    try:
        address = cluster.scheduler_address
        # The first tasks import pandas, scipy and the engine on each worker: warm them up
        # on a copy of the first specs so the timed runs compare evaluation with evaluation.
        evaluate_on_dask(specs[:4], address, rootdir=specs[0].parent)
        with _timer(times, "dask"):
            on_dask = evaluate_on_dask(specs, address, rootdir=specs[0].parent)
        with _timer(times, "dask1"):
            evaluate_on_dask(specs, address, rootdir=specs[0].parent, threads_per_spec=1)
    finally:
        with _timer(times, "stop"):
            cluster.close()
    same = on_dask == serial
    print(
        f"serial, one process:          {times['serial']:.1f} s  "
        f"({1e3 * times['serial'] / count:.0f} ms per spec)"
    )
    print(
        f"dask, 2 workers × 1 thread:    {times['dask']:.1f} s  "
        f"(speed-up {times['serial'] / times['dask']:.2f}×; results identical: {same})"
    )
    print(
        f"  same, threads_per_spec=1:    {times['dask1']:.1f} s  "
        f"(speed-up {times['serial'] / times['dask1']:.2f}×)"
    )
    print(f"  cluster start {times['start']:.1f} s, stop {times['stop']:.1f} s (not in the above)")


# ------------------------------------------------------------------------------------------
# Part 3: other tools on the same pair


def _median_time(repeats: int, call: Callable[[], str]) -> tuple[float, str]:
    runs = []
    outcome = ""
    for _ in range(repeats):
        started = time.perf_counter()
        outcome = call()
        runs.append(time.perf_counter() - started)
    return statistics.median(runs), outcome


def part_compare(n_large: int, n_iso: int) -> None:
    import pandas as pd
    from objective_rating_metrics.rating import ISO18571
    from pytest_regressions.num_regression import NumericRegressionFixture

    from pytest_hevval.core.characteristics import signal_characteristics

    rate_hz = 100.0
    dt = 1.0 / rate_hz
    print(f"\n== compare: one signal pair at {rate_hz:g} Hz (median of repeats) ==")

    def ours(ref: np.ndarray, sim: np.ndarray) -> str:
        lambdas = signal_characteristics(ref, sim, dt=dt, max_lag_s=5.0).lambdas
        return "λ1–λ6 " + " ".join(f"{v:.3f}" for v in lambdas)

    def iso(ref: np.ndarray, sim: np.ndarray) -> str:
        t = np.arange(ref.size) * dt
        rating = ISO18571(np.column_stack([t, ref]), np.column_stack([t, sim]), dt=dt)
        return f"overall rating {rating.overall_rating():.3f}"

    # The fixture's comparison needs no pytest request; its tolerances default to isclose's.
    fixture = NumericRegressionFixture.__new__(NumericRegressionFixture)
    fixture._tolerances_dict = {}
    fixture._default_tolerance = {}

    def regression(obtained: Path, expected: Path) -> str:
        fixture._check_fn(obtained, expected)
        return "passed"

    ref_all = _column(7, n_large, rate_hz, model=False)
    sim_all = _column(7, n_large, rate_hz, model=True)
    iso(ref_all[:500], sim_all[:500])  # numba compiles its DTW on first use
    rows: list[tuple[str, int, float, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (n_iso, n_large):
            ref, sim = ref_all[:n], sim_all[:n]
            # num_regression compares an output with its own stored baseline, both written
            # as it writes them (CSV, 17 significant digits); only the comparison is timed.
            files = [Path(tmp, f"{n}_obtained.csv"), Path(tmp, f"{n}.csv")]
            for path in files:
                fixture._dump_fn(pd.DataFrame({"sim": sim}), path)
            calls: list[tuple[str, int, Callable[[], str]]] = [
                ("hevval signal_characteristics", 5, partial(ours, ref, sim)),
                ("num_regression comparison step", 5, partial(regression, *files)),
            ]
            if n <= n_iso:
                calls.append(("ISO/TS 18571 (objective-rating-metrics)", 3, partial(iso, ref, sim)))
            for name, repeats, call in calls:
                seconds, outcome = _median_time(repeats, call)
                rows.append((name, n, seconds, outcome))
    for name, n, seconds, outcome in rows:
        print(f"{name:42s} n={n:>8,} {seconds * 1e3:9.1f} ms  {outcome}")


# ------------------------------------------------------------------------------------------


SIZES = {
    "quick": {
        "e2e": (60, 600.0, 100.0),
        "quality": (60, 600.0, 100.0),
        "dask": (20, 20, 600.0, 10.0),
        "compare": (60_000, 2_000),
    },
    "full": {
        "e2e": (600, 3600.0, 100.0),
        "quality": (600, 3600.0, 100.0),
        "dask": (100, 20, 600.0, 10.0),
        "compare": (360_000, 4_000),
    },
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="small sizes (default)")
    size.add_argument("--full", action="store_true", help="the target sizes")
    parser.add_argument(
        "--only", default="e2e,dask,compare", help="comma-separated parts (also: quality)"
    )
    parser.add_argument(
        "--formats", default="parquet,mf4", help="e2e: comma-separated formats (parquet, mf4)"
    )
    parser.add_argument(
        "--no-intervals",
        action="store_true",
        help="e2e: score without the bootstrap intervals (as --hevval-no-intervals)",
    )
    parser.add_argument("--child-e2e", help=argparse.SUPPRESS)
    parser.add_argument("--child-floor", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child_e2e:
        child_e2e(args.child_e2e, intervals=not args.no_intervals)
        return
    if args.child_floor:
        child_floor(args.child_floor)
        return
    sizes = SIZES["full" if args.full else "quick"]
    parts = {p.strip() for p in args.only.split(",") if p.strip()}
    unknown = parts - set(sizes)
    if unknown:
        parser.error(f"unknown part(s) {sorted(unknown)}; choose from {sorted(sizes)}")
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cores, numpy {np.__version__}")
    if "e2e" in parts:
        formats = tuple(f.strip() for f in args.formats.split(",") if f.strip())
        part_e2e(*sizes["e2e"], formats=formats, intervals=not args.no_intervals)
    if "quality" in parts:
        part_quality(*sizes["quality"])
    if "dask" in parts:
        part_dask(*sizes["dask"])
    if "compare" in parts:
        part_compare(*sizes["compare"])


if __name__ == "__main__":
    main()
