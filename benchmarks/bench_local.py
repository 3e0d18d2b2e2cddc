"""What windows and regions add to global scoring, measured side by side in one run.

Run from the repository root:

    python benchmarks/bench_local.py                        # 600 signals × 1 h at 100 Hz
    python benchmarks/bench_local.py --signals 60 --repeat 3

For ``--signals`` vehicle-like signal pairs of ``--hours`` at ``--rate`` Hz it times, interleaved
repetition by repetition on the same arrays:

* **global**: the engine's per-signal scoring, ``signal_characteristics`` (λ1–λ6, lag search),
  on ``--threads`` threads as the engine runs it;
* **local**: labelling the samples once (30 s windows × a 10 × 10 region map over two
  operating variables) plus every signal's one-pass sums and its window and cell tables
  (``score_local``), on the same threads;

and prints the ratio local / global. The compiled pass is used when numba is installed
(``--path numpy`` forces the numpy path). The goal: local adds at most 30 % to global.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pytest_hevval.core.characteristics import signal_characteristics
from pytest_hevval.core.local import fixed_windows, region_grid
from pytest_hevval.scoring.local import Labels, score_local


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


def make_labels(n: int, dt: float, window_s: float, bins: int) -> Labels:
    rng = np.random.default_rng(1)
    t = np.arange(n) * dt
    speed = 60 + 60 * np.sin(2 * np.pi * t / 600.0) + rng.normal(0, 1, n)
    torque = 100 * np.sin(2 * np.pi * t / 47.0) + rng.normal(0, 5, n)
    starts, stops = fixed_windows(n, dt, window_s)
    windows = starts.shape[0]
    edges = [np.linspace(v.min(), v.max(), bins + 1) for v in (speed, torque)]
    grid = region_grid([speed, torque], edges)
    cells = bins * bins
    window = np.arange(n, dtype=np.int64) // (stops[0] - starts[0])
    fine = window * (cells + 1) + (grid.cell + 1)
    labels = [f"cell {i}" for i in range(cells)]
    return Labels(
        fine=fine,
        shape=(windows, cells + 1),
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
    args = parser.parse_args()
    n = int(args.hours * 3600 * args.rate)
    dt = 1.0 / args.rate
    print(f"{args.signals} signals × {n} samples, {args.threads} threads, path {args.path}")
    pairs = make_pairs(args.signals, n)
    # The kernel's path is chosen by HEVVAL_KERNEL (auto leaves a cold cache on numpy).
    os.environ["HEVVAL_KERNEL"] = "numpy" if args.path == "numpy" else "numba"
    # Compile (or load the cached kernel) before timing.
    warm_labels = make_labels(n, dt, args.window_s, args.bins)
    score_local(warm_labels, pairs[0][0], pairs[0][1], 80.0, "xcorr")

    def global_pass() -> list[float]:
        def one(pair: tuple[np.ndarray, np.ndarray]) -> float:
            chars = signal_characteristics(pair[0], pair[1], dt=dt, max_lag_s=10.0, workers=1)
            return chars.reference_range

        with ThreadPoolExecutor(args.threads) as pool:
            return list(pool.map(one, pairs))

    ranges = global_pass()

    def local_pass() -> None:
        labels = make_labels(n, dt, args.window_s, args.bins)

        def one(k: int) -> None:
            score_local(labels, pairs[k][0], pairs[k][1], ranges[k], "xcorr")

        with ThreadPoolExecutor(args.threads) as pool:
            list(pool.map(one, range(len(pairs))))

    times: dict[str, list[float]] = {"global": [], "local": []}
    for _ in range(args.repeat):
        for name, run in (("global", global_pass), ("local", local_pass)):
            start = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - start)
    best = {k: min(v) for k, v in times.items()}
    median = {k: statistics.median(v) for k, v in times.items()}
    for name in times:
        print(f"{name:>7}: best {best[name]:.2f} s, median {median[name]:.2f} s")
    print(
        f"local / global: {best['local'] / best['global']:.1%} (best), "
        f"{median['local'] / median['global']:.1%} (median)"
    )


if __name__ == "__main__":
    main()
