"""The diagnosis's own statistics against statsmodels and arch, swept over series, sizes and seeds.

    nice python benchmarks/bench_stats_reference.py                 # 5 kinds × 4 sizes × 3 seeds
    nice python benchmarks/bench_stats_reference.py --seeds 10 --sizes 200 2000 20000
    nice python benchmarks/bench_stats_reference.py --sizes 200 --seeds 1 --speed 20000

Each comparison of ``tests/test_stats_reference.py`` (same library calls, options and
tolerances) is made on every persistent, random-walk, oscillating, trending and heavy-tailed
series; the script prints how many agree, per quantity, and every disagreement. statsmodels'
AR order search refits every order and takes seconds per series from 20 000 samples on, so it
runs up to ``--order-max`` samples. It also prints how far the λ intervals' AR(1) block rule
(``core/uncertainty.block_length``) lies from Politis–White's block length on each kind, both
held to the rule's 10 to 128 blocks a record.
"""

from __future__ import annotations

import os

# arch's block-length loop and statsmodels' fits use BLAS dot products: on a busy machine their
# spinning threads make them 50 times slower, which says nothing about the comparison.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import math
import sys
import timeit
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from arch.bootstrap import optimal_block_length  # noqa: E402
from statsmodels.stats.diagnostic import acorr_ljungbox  # noqa: E402
from statsmodels.tsa.ar_model import AutoReg, ar_select_order  # noqa: E402

from pytest_hevval.core.stats import (  # noqa: E402
    ar_fit,
    ar_order,
    hac_fit,
    ljung_box,
    politis_white,
)
from pytest_hevval.core.uncertainty import (  # noqa: E402
    MAX_BLOCKS,
    MIN_BLOCKS,
    block_length,
    lag1_autocorrelation,
)
from tests.strategies import SERIES_KINDS, time_series_of  # noqa: E402
from tests.test_stats_reference import _kendall_corrected, _statsmodels_hac  # noqa: E402


def compare(kind: str, n: int, seed: int, order_max: int) -> dict[str, bool]:
    """Every comparison on one series: True where the project agrees with the library."""
    residual = time_series_of(kind, n, seed, parameter=(seed % 5) / 4)
    regressor = time_series_of("oscillating", n, seed + 1000)
    u = residual - float(np.mean(residual))
    out: dict[str, bool] = {}
    x = np.column_stack([np.ones(n), regressor])
    y = 0.3 * regressor + residual
    fit = hac_fit(y, x, ar_order(u))
    expected = _statsmodels_hac(y, x, fit.phi)
    out["HAC coefficients"] = bool(np.allclose(fit.beta, expected.params, rtol=1e-7, atol=1e-9))
    out["HAC covariance"] = bool(np.allclose(fit.cov, expected.cov_params(), rtol=1e-6, atol=1e-12))
    if n <= order_max:
        top = min(10, n // 10 - 1)
        chosen = ar_select_order(u, maxlag=top, ic="bic", trend="n", glob=False)
        out["AR order"] = ar_order(u) == len(chosen.ar_lags or [])
    for p in (1, 2, 5):
        params = AutoReg(u, p, trend="n").fit().params
        out[f"AR({p}) fit"] = bool(
            np.allclose(ar_fit(u, p), _kendall_corrected(params, n - p), rtol=1e-7, atol=1e-9)
        )
    table = acorr_ljungbox(residual, lags=[10, 20])
    found = ljung_box(residual, [10, 20])
    best = int(np.argmin(table["lb_pvalue"].to_numpy()))
    out["Ljung-Box"] = bool(
        np.isclose(found.statistic, float(table["lb_stat"].iloc[best]), rtol=1e-9)
        and np.isclose(
            found.p_value, min(1.0, 2.0 * float(table["lb_pvalue"].iloc[best])), rtol=1e-6
        )
    )
    lengths = politis_white(residual)
    reference = optimal_block_length(residual).to_numpy()[0]
    out["Politis-White"] = bool(
        np.allclose([lengths.stationary, lengths.circular], reference, rtol=1e-9)
    )
    return out


def speeds(n: int) -> None:
    """Milliseconds per call, best of five, of the project's code and the library's."""
    residual = time_series_of("persistent", n, 1)
    u = residual - float(np.mean(residual))
    x = np.column_stack([np.ones(n), time_series_of("oscillating", n, 2)])
    y = x[:, 1] + residual
    phi = hac_fit(y, x, 2).phi
    top = min(10, n // 10 - 1)
    pairs = {
        "HAC fit": (lambda: hac_fit(y, x, 2), lambda: _statsmodels_hac(y, x, phi)),
        "AR order": (
            lambda: ar_order(u),
            lambda: ar_select_order(u, maxlag=top, ic="bic", trend="n", glob=False),
        ),
        "AR(2) fit": (lambda: ar_fit(u, 2), lambda: AutoReg(u, 2, trend="n").fit()),
        "Ljung-Box": (
            lambda: ljung_box(residual, [10, 20]),
            lambda: acorr_ljungbox(residual, lags=[10, 20]),
        ),
        "Politis-White": (
            lambda: politis_white(residual),
            lambda: optimal_block_length(residual),
        ),
    }
    print(f"\nms per call at n = {n} (best of 5; the library's HAC includes its two OLS fits,")
    print("the project's also its first OLS and AR fit)")
    for name, (own, library) in pairs.items():
        mine = min(timeit.repeat(own, number=1, repeat=5)) * 1e3
        theirs = min(timeit.repeat(library, number=1, repeat=5)) * 1e3
        print(f"{name:<14} project {mine:9.2f}   library {theirs:9.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[200, 2000, 20_000, 100_000])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--order-max", type=int, default=2000)
    parser.add_argument("--speed", type=int, default=20_000, help="samples for the timings")
    args = parser.parse_args()
    agree: Counter[str] = Counter()
    total: Counter[str] = Counter()
    ratios: dict[str, list[float]] = {kind: [] for kind in SERIES_KINDS}
    for kind in SERIES_KINDS:
        for n in args.sizes:
            for seed in range(args.seeds):
                for name, ok in compare(kind, n, seed, args.order_max).items():
                    total[name] += 1
                    agree[name] += ok
                    if not ok:
                        print(f"disagree: {name} on {kind}, n = {n}, seed {seed}")
                series = time_series_of(kind, n, seed, parameter=(seed % 5) / 4)
                rule = block_length(n, lag1_autocorrelation(series))
                # Politis-White held to the same limits as the rule (10 to 128 blocks).
                shortest, longest = math.ceil(n / MAX_BLOCKS), max(n // MIN_BLOCKS, 1)
                chosen = min(max(politis_white(series).circular, shortest), longest)
                ratios[kind].append(rule / chosen)
    print(f"\n{'quantity':<18} agree / compared")
    for name in total:
        print(f"{name:<18} {agree[name]:>5} / {total[name]}")
    print(f"{'all':<18} {sum(agree.values()):>5} / {sum(total.values())}")
    print("\nλ intervals' AR(1) block rule ÷ Politis-White circular block length, both held")
    print("to 10-128 blocks a record")
    for kind, values in ratios.items():
        print(f"{kind:<14} {min(values):6.2f} – {max(values):6.2f}")
    if args.speed:
        speeds(args.speed)


if __name__ == "__main__":
    main()
