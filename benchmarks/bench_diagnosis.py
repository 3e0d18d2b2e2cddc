"""Residual diagnosis of one signal: 1 h at 100 Hz with 50 candidate channels.

    python benchmarks/bench_diagnosis.py            # target: ≤ 5 s on a 2-core machine

Also checks that the one channel that really drives the residual is ranked first and that its
coefficient interval contains the injected value.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import signal as sps

from pytest_hevval.core.residual import Candidate, diagnose_residual

DT = 0.01


def ar1(rng: np.random.Generator, n: int, phi: float, sd: float = 1.0) -> np.ndarray:
    return np.asarray(sps.lfilter([1.0], [1.0, -phi], rng.standard_normal(n) * sd))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=float, default=360_000)
    parser.add_argument("--candidates", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    n = int(args.samples)
    rng = np.random.default_rng(21)
    t = np.arange(n) * DT
    simulated = 10.0 * np.sin(2 * np.pi * 0.1 * t) + 3.0 * np.sin(2 * np.pi * 0.37 * t + 1.0)
    channels = [Candidate(f"c{j}", "channel", ar1(rng, n, 0.999)) for j in range(args.candidates)]
    reference = simulated + 0.5 * channels[7].values + ar1(rng, n, 0.99, 0.05)
    times = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        found = diagnose_residual(reference, simulated, dt=DT, candidates=channels)
        times.append(time.perf_counter() - start)
    best = found.candidates[0]
    print(f"samples {n}, candidates {args.candidates}")
    print(
        f"diagnose_residual: best {min(times):.2f} s, median {sorted(times)[len(times) // 2]:.2f} s"
    )
    print(f"top candidate {best.name}, coefficient {best.coefficient:.4f} {best.interval}")
    assert best.name == "c7"
    assert best.interval[0] <= 0.5 <= best.interval[1]


if __name__ == "__main__":
    main()
