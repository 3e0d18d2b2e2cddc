"""Time report generation for a large validation (default: 600 signals).

Run from the project root::

    python benchmarks/bench_report.py               # 600 signals, html + json + md
    python benchmarks/bench_report.py --signals 60  # quicker

Two costs are measured separately, because they are paid in different places:

* ``figure_data`` for one signal of one hour at 100 Hz (360,000 samples) — paid by the engine,
  once per signal, wherever the traces live (an xdist worker, a Dask node);
* ``write_reports`` for all signals — paid once by the controller, from result dicts only.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from pytest_hevval.report import figure_data, write_reports

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.demo_results import demo_results


def _results(signals: int) -> list[dict[str, Any]]:
    """Demo specs (at most 10) holding exactly ``signals`` signals between them."""
    per_set = 7  # signals in one demo signal set
    specs = max(1, min(10, signals // per_set))
    sets = -(-signals // (specs * per_set))
    results = demo_results(specs=specs, sets_per_spec=sets, duration_s=600.0, rate_hz=10.0)
    remaining = signals
    for spec in results:
        keep = min(len(spec["signals"]), remaining)
        spec["signals"] = spec["signals"][:keep]
        remaining -= keep
    return [spec for spec in results if spec["signals"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--signals", type=int, default=600)
    parser.add_argument("--formats", default="html,json,md")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    n = 360_000
    ref = np.cumsum(rng.normal(0.0, 1.0, n))
    sim = np.roll(ref, 20) + rng.normal(0.0, 0.5, n)
    figure_data(ref[:1000], sim[:1000], dt=0.01, start_s=0.0, max_lag=10)
    timings = {}
    for max_lag in (500, 36_000):
        runs = []
        for _ in range(7):
            start = time.perf_counter()
            figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=max_lag)
            runs.append(time.perf_counter() - start)
        timings[max_lag] = statistics.median(runs)
    print(
        f"figure_data, 360,000 samples: median {timings[500] * 1e3:.1f} ms (max_lag 5 s), "
        f"{timings[36_000] * 1e3:.1f} ms (max_lag 360 s)"
    )

    results = _results(args.signals)
    count = sum(len(spec["signals"]) for spec in results)
    formats = {f.strip() for f in args.formats.split(",")}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        paths = write_reports(results, formats, Path(tmp), title="benchmark")
        elapsed = time.perf_counter() - start
        sizes = ", ".join(f"{p.name} {p.stat().st_size / 1e6:.1f} MB" for p in paths)
    print(f"write_reports, {count} signals in {len(results)} specs: {elapsed:.1f} s ({sizes})")


if __name__ == "__main__":
    main()
