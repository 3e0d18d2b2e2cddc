"""What windows and regions add to global scoring, measured side by side in one run.

Run from the repository root:

    python benchmarks/bench_local.py                        # 600 signals × 1 h at 100 Hz
    python benchmarks/bench_local.py --signals 60 --repeat 3
    python benchmarks/bench_local.py --labels noisy         # a cell change every third sample
    python benchmarks/bench_local.py --engine --repeat 3    # `hevval run`, process to process

For ``--signals`` vehicle-like signal pairs of ``--hours`` at ``--rate`` Hz it times, interleaved
repetition by repetition on the same arrays, on ``--threads`` threads as the engine runs them:

* **global**: each signal's ``signal_characteristics`` (λ1–λ6, lag search);
* **global + local**: labelling the samples once (30 s windows × a 10 × 10 region map over two
  operating variables: binning, the fine labels and their ``Grouping``), then each signal's
  ``signal_characteristics`` followed by its one-pass sums (``local_sums``), in the same task,
  and every signal's window and cell tables in one call after them (``local_results``), as the
  engine scores a spec;

and prints what local adds, (global + local − global) / global, in wall and in CPU time (the
CPU time of the process is less moved by other jobs on a shared machine). The goal: at most
30 %.

With ``--engine`` it times ``hevval run`` instead, process to process, as a user runs it: the
600-signal hour of ``bench_scale.py`` (``python benchmarks/bench_scale.py --full --only e2e
--formats parquet`` makes it) against a copy of its spec with ``local: {window_s: 30}`` and a
10 × 10 ``regions:`` map over two of its channels, alternately, ``--repeat`` times each, and
prints what the windows and regions add to the whole run (reading, scoring, intervals and
publishing the results; ``--json`` also writes the results file).

The operating variables (``--labels``): ``drive`` (default) bins the speed and heater power of
the i3 trip B03 of the example project (10 Hz, interpolated to the rate and repeated to the
length), whose cell changes at about one sample in a hundred at 100 Hz; ``noisy`` bins two
sines with white noise, whose cell changes at about a third of the samples. The compiled pass
is used when numba is installed (``--path numpy`` forces the numpy path).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pytest_hevval.core import local
from pytest_hevval.core.characteristics import signal_characteristics
from pytest_hevval.core.groups import fixed_windows, region_grid
from pytest_hevval.scoring import local as scoring_local
from pytest_hevval.scoring.local import Labels, score_local

ROOT = Path(__file__).resolve().parents[1]
TRIP = ROOT / "example_project" / "data" / "i3" / "TripB03.parquet"
TRIP_VARIABLES = ("Velocity [km/h]", "Heating Power CAN [kW]")


def make_pairs(signals: int, n: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    pairs = []
    base = np.sin(2 * np.pi * t / 97.0) * 40 + np.sin(2 * np.pi * t / 13.0) * 7
    for k in range(signals):
        ref = base * (1 + 0.01 * k) + rng.normal(0, 1.0, n)
        sim = np.roll(ref, 5) * 0.98 + rng.normal(0, 0.5, n)
        pairs.append((ref, sim))
    return pairs


#: Code before 2026-11-27 took the fine labels themselves and summed them in a pass of its
#: own: kept to compare side by side.
grouped = "grouping" in Labels.__dataclass_fields__
batched = hasattr(scoring_local, "local_results")


def operating_variables(n: int, dt: float, kind: str) -> list[np.ndarray]:
    """Two operating variables of ``n`` samples: a real trip's speed and heater power, or
    noisy sines."""
    t = np.arange(n) * dt
    if kind == "drive":
        trip = pq.read_table(TRIP, columns=["Time [s]", *TRIP_VARIABLES])
        logged = trip.column("Time [s]").to_numpy()
        on_trip = t % logged[-1]
        return [np.interp(on_trip, logged, trip.column(name).to_numpy()) for name in TRIP_VARIABLES]
    rng = np.random.default_rng(1)
    speed = 60 + 60 * np.sin(2 * np.pi * t / 600.0) + rng.normal(0, 1, n)
    torque = 100 * np.sin(2 * np.pi * t / 47.0) + rng.normal(0, 5, n)
    return [speed, torque]


def make_labels(variables: list[np.ndarray], dt: float, window_s: float, bins: int) -> Labels:
    """What ``label_samples`` builds for a spec with ``local: {window_s}`` and a region map."""
    n = variables[0].shape[0]
    starts, stops = fixed_windows(n, dt, window_s)
    windows = starts.shape[0]
    edges = [np.linspace(v.min(), v.max(), bins + 1) for v in variables]
    grid = region_grid(variables, edges)
    cells = bins * bins
    window = np.arange(n, dtype=np.int64) // (stops[0] - starts[0])
    fine = window * (cells + 1) + (grid.cell + 1)
    labels = [f"cell {i}" for i in range(cells)]
    shape = (windows, cells + 1)
    layout = (
        {"grouping": local.Grouping.of(fine, shape)} if grouped else {"fine": fine, "shape": shape}
    )
    return Labels(
        **layout,
        windows=windows,
        spans_s=tuple((float(a) * dt, float(b) * dt) for a, b in zip(starts, stops, strict=True)),
        window_starts=starts,
        window_stops=stops,
        window_labels=tuple(f"{a * dt:.0f} s" for a in starts),
        dt=dt,
        start_s=0.0,
        cell_axis=1,
        region={"labels": labels, "shape": [bins, bins]},
    )


def fine_labels(labels: Labels) -> np.ndarray:
    grouping = getattr(labels, "grouping", None)
    return grouping.group if grouping is not None else np.asarray(vars(labels)["fine"])


def engine_runs(repeat: int, json_file: bool) -> None:
    """``hevval run`` of the 600-signal hour with and without windows and regions."""
    folder = ROOT / "benchmarks" / ".data" / "e2e-600x360000"
    plain = folder / "parquet.hevval.yaml"
    if not plain.exists():
        sys.exit(
            f"{plain} is missing: make it with "
            "`python benchmarks/bench_scale.py --full --only e2e --formats parquet`"
        )
    localised = folder / "local.hevval.yaml"
    text = plain.read_text().replace("name: scale-parquet", "name: scale-local")
    text = text.replace(
        "thresholds: {mae: 0.5}\n",
        "thresholds: {mae: 0.5}\nlocal: {window_s: 30}\n"
        "regions: {by: [c000, c001], bins: [10, 10]}\n",
        1,
    )
    localised.write_text(text)
    times: dict[str, list[float]] = {"plain": [], "local": []}
    with tempfile.TemporaryDirectory() as out:
        for _ in range(repeat):
            for name, spec in (("plain", plain), ("local", localised)):
                command = [sys.executable, "-m", "pytest_hevval", "run", str(spec)]
                command += ["--quiet", "--no-history"]
                if json_file:
                    command += ["--json", str(Path(out) / f"{name}.json")]
                start = time.perf_counter()
                subprocess.run(command, cwd=out, capture_output=True, check=False)
                times[name].append(time.perf_counter() - start)
    for name, measured in times.items():
        print(f"{name:>6}: " + ", ".join(f"{t:.2f}" for t in measured) + " s")
    added = [b - a for a, b in zip(times["plain"], times["local"], strict=True)]
    ratio = [b / a - 1.0 for a, b in zip(times["plain"], times["local"], strict=True)]
    print(
        f"local adds {statistics.median(added):.2f} s to the run (median of the pairs; "
        f"{min(added):.2f}–{max(added):.2f} s), {statistics.median(ratio):.1%}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--signals", type=int, default=600)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--window-s", type=float, default=30.0)
    parser.add_argument("--bins", type=int, default=10)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--path", choices=("numba", "numpy"), default="numba")
    parser.add_argument("--labels", choices=("drive", "noisy"), default="drive")
    parser.add_argument("--engine", action="store_true", help="time `hevval run` instead")
    parser.add_argument("--json", action="store_true", help="with --engine: write --json too")
    args = parser.parse_args()
    if args.engine:
        engine_runs(args.repeat, args.json)
        return
    n = int(args.hours * 3600 * args.rate)
    dt = 1.0 / args.rate
    print(f"{args.signals} signals × {n} samples, {args.threads} threads, path {args.path}")
    pairs = make_pairs(args.signals, n)
    variables = operating_variables(n, dt, args.labels)
    # The kernel's path is chosen by HEVVAL_KERNEL (auto leaves a cold cache on numpy).
    os.environ["HEVVAL_KERNEL"] = "numpy" if args.path == "numpy" else "numba"
    warm = make_labels(variables, dt, args.window_s, args.bins)
    changes = np.count_nonzero(np.diff(fine_labels(warm))) / max(n - 1, 1)
    print(f"labels {args.labels}: the group changes at {changes:.2%} of the samples")

    def characteristics(pair: tuple[np.ndarray, np.ndarray]) -> float:
        chars = signal_characteristics(pair[0], pair[1], dt=dt, max_lag_s=10.0, workers=1)
        return chars.reference_range

    # Compile (or load the cached kernel) before timing.
    score_local(warm, pairs[0][0], pairs[0][1], characteristics(pairs[0]), "xcorr")

    def global_pass() -> None:
        with ThreadPoolExecutor(args.threads) as pool:
            list(pool.map(characteristics, pairs))

    def with_local() -> None:
        labels = make_labels(variables, dt, args.window_s, args.bins)

        def one(pair: tuple[np.ndarray, np.ndarray]) -> Any:
            if not grouped:  # code before 2026-11-27: a pass of its own
                score_local(labels, pair[0], pair[1], characteristics(pair), "xcorr")
                return None
            # As the engine scores a signal: its groups summed along with λ.
            chars = signal_characteristics(
                pair[0],
                pair[1],
                dt=dt,
                max_lag_s=10.0,
                workers=1,
                group_runs=labels.grouping.runs(pair[0], pair[1]),
            )
            if not batched:  # code before e0a7683: each signal's tables on its thread
                score_local(labels, *pair, chars.reference_range, "xcorr", chars.group_sums)
                return None
            return scoring_local.local_sums(labels, *pair, chars.reference_range, chars.group_sums)

        with ThreadPoolExecutor(args.threads) as pool:
            sums = list(pool.map(one, pairs))
        if batched:  # as the engine does: every signal's tables in one call after the pass
            scoring_local.local_results(labels, sums, "xcorr")

    times: dict[str, list[float]] = {"global": [], "global + local": []}
    cpu: dict[str, list[float]] = {"global": [], "global + local": []}
    for _ in range(args.repeat):
        for name, run in (("global", global_pass), ("global + local", with_local)):
            start, start_cpu = time.perf_counter(), time.process_time()
            run()
            times[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    for name in times:
        print(
            f"{name:>14}: wall best {min(times[name]):.2f} s, median "
            f"{statistics.median(times[name]):.2f} s; CPU best {min(cpu[name]):.2f} s, "
            f"median {statistics.median(cpu[name]):.2f} s"
        )
    for label, measured in (("wall", times), ("CPU", cpu)):
        both, alone = measured["global + local"], measured["global"]
        added = [b / a - 1.0 for b, a in zip(both, alone, strict=True)]
        print(
            f"local adds ({label}): {min(both) / min(alone) - 1.0:.1%} best against best, "
            f"{statistics.median(added):.1%} median of the repetitions' ratios"
        )


if __name__ == "__main__":
    main()
