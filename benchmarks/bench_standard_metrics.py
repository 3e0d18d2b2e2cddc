"""The standard metrics beside their reference implementation, side by side in one run.

    python benchmarks/bench_standard_metrics.py                    # n = 1,000 and 4,000
    python benchmarks/bench_standard_metrics.py --samples 4000 --repeat 5
    python benchmarks/bench_standard_metrics.py --long 14130 360000   # ours alone, long records
    python benchmarks/bench_standard_metrics.py --samples --banded 88   # banded vs exact, i3
    python benchmarks/bench_standard_metrics.py --samples --engine 600   # through the engine

ISO/TS 18571: ``objective-rating-metrics`` (``ISO18571(...).overall_rating()``, its numba
compilation done once before timing) against ``iso18571_rating`` on the numpy path and, with
the ``fast`` extra, on the compiled kernel (compiled before timing), on the drive-cycle pair of
``bench_core.py``, interleaved repetition by repetition; the ratio is taken per repetition and
the two ratings are printed so that they can be compared. The other standard metrics are
single passes; their times at the same size are printed for scale.

``--engine N``: a spec of N signals × 1 h at 100 Hz (``bench_scale.py``'s end-to-end data)
scored by the engine as ``hevval run`` scores it, without and with every standard metric but
ISO/TS 18571 (``ENGINE_METRICS``), interleaved; wall and CPU time of each, and the metrics'
share.
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


def _on_path(path: str, ref: np.ndarray, sim: np.ndarray) -> Any:
    """``iso18571_rating`` on the numpy reference path or the compiled kernel."""
    from pytest_hevval.core.kernel import KERNEL_ENV
    from pytest_hevval.core.standard import iso18571_rating

    os.environ[KERNEL_ENV] = path
    try:
        return iso18571_rating(ref, sim)
    finally:
        del os.environ[KERNEL_ENV]


#: The standard metrics ``--engine`` switches on: all but ISO/TS 18571, whose warping costs
#: seconds per hour-long signal by itself.
ENGINE_METRICS = "[theil, sprague_geers, russell, kge, kge2012, nse, cvrmse, nmbe]"


def _engine(signals: int, repeat: int) -> None:
    from bench_scale import e2e_data

    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import load_spec

    folder = e2e_data(signals, 3600.0, 100.0)
    plain = folder / "parquet.hevval.yaml"
    text = plain.read_text().replace(
        "thresholds: {mae: 0.5}", f"thresholds: {{mae: 0.5}}\nmetrics: {ENGINE_METRICS}"
    )
    metrics = folder / "metrics.hevval.yaml"
    metrics.write_text(text)
    times: dict[str, list[tuple[float, float]]] = {"without": [], "with": []}
    for _ in range(repeat):
        for label, path in (("without", plain), ("with", metrics)):
            spec = load_spec(path)
            wall, cpu = time.perf_counter(), time.process_time()
            evaluate_spec(spec)
            times[label].append((time.perf_counter() - wall, time.process_time() - cpu))
            print(
                f"  {label:7s} metrics: {times[label][-1][0]:.2f} s wall, "
                f"{times[label][-1][1]:.2f} s CPU",
                flush=True,
            )
    best = {k: (min(w for w, _ in v), min(c for _, c in v)) for k, v in times.items()}
    print(
        f"{signals} signals × 1 h, best of {repeat}: without {best['without'][0]:.2f} s wall "
        f"({best['without'][1]:.2f} s CPU), with {best['with'][0]:.2f} s wall "
        f"({best['with'][1]:.2f} s CPU): the metrics add "
        f"{best['with'][0] / best['without'][0] - 1:.0%} wall, "
        f"{best['with'][1] / best['without'][1] - 1:.0%} CPU"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, nargs="*", default=[1000, 4000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--long", type=int, nargs="*", default=[], help="ours alone at these n")
    parser.add_argument(
        "--banded",
        type=int,
        nargs="*",
        default=[],
        help="warping half-bands: banded against exact rating on every signal of two i3 trips",
    )
    parser.add_argument("--engine", type=int, default=0, help="signals scored by the engine")
    args = parser.parse_args()
    if args.engine:
        _engine(args.engine, args.repeat)

    from pytest_hevval.core import kernel
    from pytest_hevval.core.registry import STANDARD_CHARACTERISTICS, get_characteristic

    paths = ["numpy"] + (["numba"] if kernel.active_path() == "numba" else [])
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; paths {paths}")
    if args.samples:
        warm_ref, warm_sim = make_pair("drive", 64)
        t_jit, _ = _timed(_package, warm_ref, warm_sim)
        print(
            f"objective-rating-metrics first call (numba compilation, not counted): {t_jit:.2f} s"
        )
        for path in paths:
            t_warm, _ = _timed(_on_path, path, warm_ref, warm_sim)
            print(f"ours on {path}, first call (not counted): {t_warm:.2f} s")
    for n in args.samples:
        ref, sim = make_pair("drive", n)
        theirs: list[float] = []
        ours: dict[str, list[float]] = {path: [] for path in paths}
        ratios: dict[str, list[float]] = {path: [] for path in paths}
        ratings: dict[str, float] = {}
        for _ in range(args.repeat):
            t_pkg, r_pkg = _timed(_package, ref, sim)
            theirs.append(t_pkg)
            for path in paths:
                t_ours, r_ours = _timed(_on_path, path, ref, sim)
                ours[path].append(t_ours)
                ratios[path].append(t_pkg / t_ours)
                ratings[path] = r_ours.rating
        print(f"ISO/TS 18571 n = {n:6d}: package {min(theirs) * 1e3:9.1f} ms (rating {r_pkg:.4f})")
        for path in paths:
            print(
                f"    ours, {path:5s}: {min(ours[path]) * 1e3:9.2f} ms (rating {ratings[path]:.4f})"
                f"   package/ours min {min(ratios[path]):.0f}x"
                f" median {statistics.median(ratios[path]):.0f}x"
            )
        for name in STANDARD_CHARACTERISTICS[1:]:
            compute = get_characteristic(name).compute
            assert compute is not None
            best = min(_timed(compute, ref, sim, DT)[0] for _ in range(args.repeat))
            print(f"    {name:14s} n = {n:6d}: {best * 1e3:7.3f} ms")
    for n in args.long:
        ref, sim = make_pair("drive", n)
        for path in paths:
            t_ours, rating = _timed(_on_path, path, ref, sim)
            mode = f"banded to ±{rating.band}" if rating.banded else f"exact band ±{rating.band}"
            print(
                f"ISO/TS 18571 n = {n:6d}, {path:5s}: {t_ours:.2f} s, {mode}, "
                f"rating {rating.rating:.4f}"
            )

    for band in args.banded:
        banded_deviation(band)


def banded_deviation(band: int) -> None:
    """The rating with the warping band narrowed to ±band against the exact one, i3 trips."""
    from pytest_hevval.core.standard import iso18571_rating
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import load_spec

    example = Path(__file__).resolve().parent.parent / "example_project"
    for name in ("i3-A02-motorway-v2", "i3-B03-winter-v2"):
        spec = load_spec(example / "specs" / f"{name}.hevval.yaml")
        arrays = evaluate_spec(spec, rootdir=example, keep_arrays=True).arrays
        for path, (ref, sim) in arrays.items():
            exact = iso18571_rating(ref, sim)
            narrow = iso18571_rating(ref, sim, max_cells=ref.size * (2 * band + 1))
            print(
                f"{name} {path:24s} n = {ref.size}: exact ±{exact.band} {exact.rating:.4f}, "
                f"±{narrow.band} {narrow.rating:.4f} ({narrow.rating - exact.rating:+.5f}; "
                f"magnitude {narrow.magnitude - exact.magnitude:+.5f})"
            )


if __name__ == "__main__":
    main()
