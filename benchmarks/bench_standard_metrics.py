"""The standard metrics beside their reference implementation, side by side in one run.

    python benchmarks/bench_standard_metrics.py                    # n = 1,000 and 4,000
    python benchmarks/bench_standard_metrics.py --samples 4000 --repeat 5
    python benchmarks/bench_standard_metrics.py --long 14130 360000   # ours alone, long records

ISO/TS 18571: ``objective-rating-metrics`` (``ISO18571(...).overall_rating()``, its numba
compilation done once before timing) against ``iso18571_rating``, on the drive-cycle pair of
``bench_core.py``, interleaved repetition by repetition; the ratio is taken per repetition and
the two ratings are printed so that they can be compared. The other standard metrics are
single passes; their times at the same size are printed for scale.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_core import DT, make_pair


def _timed(call: Callable[..., Any], *args: Any) -> tuple[float, Any]:
    start = time.perf_counter()
    out = call(*args)
    return time.perf_counter() - start, out


def _package(ref: np.ndarray, sim: np.ndarray) -> float:
    from objective_rating_metrics.rating import ISO18571

    t = np.arange(ref.size) * DT
    return float(ISO18571(np.c_[t, ref], np.c_[t, sim], dt=DT).overall_rating(-1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, nargs="*", default=[1000, 4000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--long", type=int, nargs="*", default=[], help="ours alone at these n")
    args = parser.parse_args()

    from pytest_hevval.core.registry import STANDARD_CHARACTERISTICS, get_characteristic
    from pytest_hevval.core.standard import iso18571_rating

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    warm_ref, warm_sim = make_pair("drive", 64)
    t_jit, _ = _timed(_package, warm_ref, warm_sim)
    print(f"objective-rating-metrics first call (numba compilation, not counted): {t_jit:.2f} s")
    for n in args.samples:
        ref, sim = make_pair("drive", n)
        ratios, theirs, ours = [], [], []
        for _ in range(args.repeat):
            t_pkg, r_pkg = _timed(_package, ref, sim)
            t_ours, r_ours = _timed(iso18571_rating, ref, sim)
            theirs.append(t_pkg)
            ours.append(t_ours)
            ratios.append(t_pkg / t_ours)
        print(
            f"ISO/TS 18571 n = {n:6d}: package {min(theirs) * 1e3:9.1f} ms (rating {r_pkg:.4f})"
            f"   ours {min(ours) * 1e3:7.1f} ms (rating {r_ours.rating:.4f})"
            f"   package/ours min {min(ratios):.0f}x median {statistics.median(ratios):.0f}x"
        )
        for name in STANDARD_CHARACTERISTICS[1:]:
            compute = get_characteristic(name).compute
            assert compute is not None
            best = min(_timed(compute, ref, sim, DT)[0] for _ in range(args.repeat))
            print(f"    {name:14s} n = {n:6d}: {best * 1e3:7.3f} ms")
    for n in args.long:
        ref, sim = make_pair("drive", n)
        t_ours, rating = _timed(iso18571_rating, ref, sim)
        mode = f"banded to ±{rating.band}" if rating.banded else f"exact band ±{rating.band}"
        print(f"ISO/TS 18571 n = {n:6d}: ours {t_ours:.2f} s, {mode}, rating {rating.rating:.4f}")


if __name__ == "__main__":
    main()
