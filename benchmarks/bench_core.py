"""Speed, memory and lag exactness of the metric core on long, vehicle-like signal pairs.

Run from the repository root:

    python benchmarks/bench_core.py                      # quick: 2·10^6 samples
    python benchmarks/bench_core.py --samples 1e7 1e8    # the figures in docs/performance.md
    python benchmarks/bench_core.py --paths --samples 5e7 1e8   # numpy path against the kernel

For every size and test signal it prints, measured side by side in one process:

* the floor: ``ref.sum(); sim.sum()``, one read of both arrays by numpy;
* ``signal_characteristics`` (λ1–λ6 plus the ±10 s lag search);
* the straightforward composition a user would write: ``scipy.signal.correlate`` over the whole
  records (``method="fft"``) plus plain numpy for MAE, RMS, σ, λ1, λ2;
* peak extra memory of each, in a fresh subprocess (VmHWM growth, and tracemalloc's peak);
* whether the lag equals the argmax of the exact mean-removed cross-correlation within ±max_lag.

Separately, at sizes they can handle: ISO/TS 18571 as implemented by ``objective-rating-metrics``
and the comparison step of pytest-regressions' ``num_regression``, each beside ours on the same
pair.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy
import scipy.fft
from scipy import signal as sps

from pytest_hevval.core.characteristics import signal_characteristics

FloatArray = npt.NDArray[np.float64]

DT = 0.01  # 100 Hz, as in the paper's drive data
SIGNALS = ("drive", "noise")
# Injected delays in samples: the simulation lags the measurement, so the peak is at −delay.
DELAYS = {"drive": 23, "noise": 137}
_GEN_CHUNK = 1 << 22


# --- Test signals ----------------------------------------------------------------------------


def _lowpass_noise(
    rng: np.random.Generator, n: int, cutoff_hz: float, out: FloatArray | None = None
) -> FloatArray:
    """Unit-variance-ish white noise through a 4th-order Butterworth low-pass, in chunks."""
    sos = sps.butter(4, cutoff_hz, fs=1.0 / DT, output="sos")
    result = np.empty(n) if out is None else out
    zi = np.zeros((sos.shape[0], 2))
    gain = math.sqrt(0.5 / (cutoff_hz * DT))  # keeps the band-limited variance near 1
    for start in range(0, n, _GEN_CHUNK):
        stop = min(start + _GEN_CHUNK, n)
        filtered, zi = sps.sosfilt(sos, rng.standard_normal(stop - start), zi=zi)
        result[start:stop] = filtered * gain
    return result


def _drive_cycle(rng: np.random.Generator, n: int) -> FloatArray:
    """A vehicle speed trace in km/h: stops, accelerations, cruises, speed changes, braking."""
    knots_t = [0.0]
    knots_v = [0.0]
    t = 0.0
    v = 0.0
    end = n * DT
    while t < end:
        if v == 0.0:
            t += rng.uniform(3, 40)  # standing
            knots_t.append(t)
            knots_v.append(0.0)
        target = float(
            rng.choice([0.0, rng.uniform(15, 60), rng.uniform(50, 130)], p=[0.25, 0.45, 0.3])
        )
        accel = rng.uniform(0.6, 2.5) if target > v else rng.uniform(0.8, 3.5)  # m/s²
        t += max(abs(target - v) / 3.6 / accel, 0.5)
        knots_t.append(t)
        knots_v.append(target)
        v = target
        if v > 0:
            t += rng.uniform(5, 240)  # cruise
            knots_t.append(t)
            knots_v.append(v)
    speed = np.empty(n)
    kt = np.asarray(knots_t)
    kv = np.asarray(knots_v)
    for start in range(0, n, _GEN_CHUNK):
        stop = min(start + _GEN_CHUNK, n)
        speed[start:stop] = np.interp(np.arange(start, stop) * DT, kt, kv)
    # Road grade and driver: small slow wander while moving.
    wander = _lowpass_noise(rng, n, 0.05)
    for start in range(0, n, _GEN_CHUNK):
        stop = min(start + _GEN_CHUNK, n)
        part = speed[start:stop]
        part += 0.8 * wander[start:stop] * np.minimum(part / 10.0, 1.0)
        np.maximum(part, 0.0, out=part)
    return speed


def make_pair(kind: str, n: int, seed: int = 20240607) -> tuple[FloatArray, FloatArray]:
    """(measured reference, simulated) of length n; the simulation lags by DELAYS[kind]."""
    rng = np.random.default_rng(seed)
    delay = DELAYS[kind]
    if kind == "drive":
        truth = _drive_cycle(rng, n + delay)
        sensor_sd, quantum, gain, bias, model_sd = 0.08, 0.01, 0.985, 0.4, 0.6
    elif kind == "noise":
        # A torque-like band-limited signal (N·m) around an operating point.
        truth = _lowpass_noise(rng, n + delay, 0.8)
        truth *= 35.0
        truth += 120.0
        sensor_sd, quantum, gain, bias, model_sd = 1.5, 0.1, 0.97, -2.0, 4.0
    else:
        raise ValueError(f"unknown signal {kind!r}")
    reference = np.empty(n)
    simulated = np.empty(n)
    model_error = _lowpass_noise(rng, n, 0.2)
    for start in range(0, n, _GEN_CHUNK):
        stop = min(start + _GEN_CHUNK, n)
        measured = truth[start + delay : stop + delay] + rng.normal(0, sensor_sd, stop - start)
        reference[start:stop] = np.round(measured / quantum) * quantum
        simulated[start:stop] = gain * truth[start:stop] + bias + model_sd * model_error[start:stop]
    return reference, simulated


def cached_pair(kind: str, n: int, cache: Path) -> tuple[Path, Path]:
    """Generate once, keep as .npy so that every subprocess loads identical data quickly."""
    cache.mkdir(parents=True, exist_ok=True)
    paths = (cache / f"{kind}-{n}-ref.npy", cache / f"{kind}-{n}-sim.npy")
    if not all(p.exists() for p in paths):
        reference, simulated = make_pair(kind, n)
        for path, data in zip(paths, (reference, simulated), strict=True):
            partial = path.with_suffix(".tmp.npy")
            np.save(partial, data)
            partial.replace(path)
    return paths


def load_pair(paths: tuple[Path, Path]) -> tuple[FloatArray, FloatArray]:
    return np.load(paths[0]), np.load(paths[1])


# --- What is compared --------------------------------------------------------------------------


def floor(reference: FloatArray, simulated: FloatArray) -> None:
    reference.sum()
    simulated.sum()


def ours(reference: FloatArray, simulated: FloatArray, max_lag_s: float) -> dict[str, float]:
    got = signal_characteristics(reference, simulated, dt=DT, max_lag_s=max_lag_s)
    return {
        "mae": got.mae,
        "rms": got.rms,
        "error_std": got.error_std,
        "lambda1": got.lambdas[0],
        "lambda2": got.lambdas[1],
        "range": got.reference_range,
        "lag": round(got.lag_s / DT),
    }


def straightforward(
    reference: FloatArray, simulated: FloatArray, max_lag_s: float
) -> dict[str, float]:
    """What a user would write with numpy and scipy, without a streaming core."""
    n = reference.shape[0]
    max_lag = min(round(max_lag_s / DT), n - 1)
    error = reference - simulated
    d_ref = np.zeros(n)
    d_sim = np.zeros(n)
    d_ref[1:-1] = reference[2:] - reference[:-2]
    d_sim[1:-1] = simulated[2:] - simulated[:-2]
    full = sps.correlate(
        reference - reference.mean(), simulated - simulated.mean(), mode="full", method="fft"
    )
    window = full[n - 1 - max_lag : n + max_lag]
    return {
        "mae": float(np.mean(np.abs(error))),
        "rms": float(np.sqrt(np.mean(error**2))),
        "error_std": float(np.std(error, ddof=1)),
        "lambda1": float(
            np.dot(reference, simulated)
            / np.sqrt(np.dot(reference, reference) * np.dot(simulated, simulated))
        ),
        "lambda2": float(np.mean(np.sign(d_ref) == np.sign(d_sim))),
        "range": float(reference.max() - reference.min()),
        "lag": int(np.argmax(window)) - max_lag,
    }


# --- Exact correlation within the lag window ---------------------------------------------------


def windowed_correlations(
    reference: FloatArray, simulated: FloatArray, max_lag: int, block: int = 1 << 17
) -> tuple[FloatArray, FloatArray]:
    """Two exact mean-removed cross-correlations C(m), |m| ≤ max_lag (index m + max_lag).

    * over each lag's whole overlap: Σ_n (ref[n+m] − μ_ref)(sim[n] − μ_sim), the classical
      full cross-correlation;
    * over the fixed window n ∈ [max_lag, N − max_lag), as the library defines it.

    Exact up to FFT rounding and affordable at 10^8 samples: the simulated record is cut into
    blocks; each block is correlated with the reference segment it can reach within the lag
    window (zero outside the record, so every lag sums over exactly its overlap), and the
    cross-spectra are added up so that one inverse FFT per result ends the work.
    """
    n = reference.shape[0]
    size = max(block, 1 << math.ceil(math.log2(8 * max_lag + 1)))
    step = size - 2 * max_lag
    mu_r = float(np.mean(reference))
    mu_s = float(np.mean(simulated))
    overlap = np.zeros(size // 2 + 1, dtype=np.complex128)
    fixed = np.zeros(size // 2 + 1, dtype=np.complex128)
    seg = np.empty(size)
    blk = np.empty(size)
    for a in range(0, n, step):
        b = min(a + step, n)
        lo = a - max_lag
        first = max(lo, 0)
        last = min(b + max_lag, n)
        seg[:] = 0.0
        seg[first - lo : last - lo] = reference[first:last]
        seg[first - lo : last - lo] -= mu_r
        spectrum_r = scipy.fft.rfft(seg, workers=2)
        blk[:] = 0.0
        blk[: b - a] = simulated[a:b]
        blk[: b - a] -= mu_s
        product = spectrum_r * np.conj(scipy.fft.rfft(blk, workers=2))
        overlap += product
        if a >= max_lag and b <= n - max_lag:
            fixed += product
        else:
            keep_lo = max(a, max_lag) - a
            keep_hi = min(b, n - max_lag) - a
            blk[:keep_lo] = 0.0
            blk[max(keep_hi, keep_lo) :] = 0.0
            fixed += spectrum_r * np.conj(scipy.fft.rfft(blk, workers=2))
    width = 2 * max_lag + 1
    return (
        np.asarray(scipy.fft.irfft(overlap, size, workers=2)[:width], dtype=np.float64),
        np.asarray(scipy.fft.irfft(fixed, size, workers=2)[:width], dtype=np.float64),
    )


def direct_correlation(
    reference: FloatArray, simulated: FloatArray, lag: int, first: int, last: int
) -> float:
    """Σ (ref[n+lag] − μ)(sim[n] − μ) for n in [first, last), summed directly in chunks."""
    mu_r = float(np.mean(reference))
    mu_s = float(np.mean(simulated))
    parts = []
    for a in range(first, last, 1 << 20):
        b = min(a + (1 << 20), last)
        parts.append(float(np.dot(reference[a + lag : b + lag] - mu_r, simulated[a:b] - mu_s)))
    return math.fsum(parts)


def reference_energy(reference: FloatArray, first: int, last: int) -> float:
    """Σ (ref[j] − μ)² for j in [first, last)."""
    mu_r = float(np.mean(reference))
    parts = []
    for a in range(first, last, 1 << 20):
        part = reference[a : min(a + (1 << 20), last)] - mu_r
        parts.append(float(np.dot(part, part)))
    return math.fsum(parts)


def _best_lag(values: FloatArray, max_lag: int, score: Callable[[int], float]) -> tuple[int, float]:
    """Argmax of ``values`` (lag m at index m + max_lag), settled by direct sums near the top.

    FFT rounding is about 1e-13 of the peak, so every lag within 1e-9 of it is re-summed
    directly and the verdict does not rest on FFT rounding. Returns the lag and the relative
    gap to the runner-up.
    """
    order = np.argsort(values)[::-1]
    peak = float(values[order[0]])
    margin = (peak - float(values[order[1]])) / abs(peak) if peak else 0.0
    close = [int(i) - max_lag for i in order[:8] if values[i] >= peak - 1e-9 * abs(peak)]
    if len(close) == 1:
        return close[0], margin
    direct = {m: score(m) for m in close}
    top = max(direct.values())
    # The library's tie rule: within 1e-12 of the peak, the lag closest to zero wins.
    tied = [m for m in close if direct[m] >= top - 1e-12 * abs(top)]
    return min(tied, key=abs), margin


@dataclass
class Exactness:
    found_lag: int
    overlap_lag: int  # argmax of the classical full cross-correlation
    overlap_margin: float  # relative gap from its peak to the runner-up
    library_lag: int  # argmax of the library's definition, computed here independently
    library_margin: float
    library_fft_lag: int | None = None  # the library's own exact FFT search on the record

    @property
    def equal(self) -> bool:
        return self.library_lag == self.found_lag


def check_exactness(
    reference: FloatArray, simulated: FloatArray, max_lag_s: float, found: int, library_max: int
) -> Exactness:
    """Where the exact correlations peak, by both definitions, against the lag we found.

    The library's definition (module docstring of pytest_hevval.core.lag): over the fixed
    window n ∈ [L, N − L), the largest C(m)/√E(m) with E(m) the reference's centred energy
    in the window that lag m reads.
    """
    n = reference.shape[0]
    max_lag = min(round(max_lag_s / DT), n // 4)
    overlap, fixed = windowed_correlations(reference, simulated, max_lag)
    lags = np.arange(-max_lag, max_lag + 1)
    mu_r = float(np.mean(reference))
    head = np.concatenate(([0.0], np.cumsum((reference[: 2 * max_lag + 1] - mu_r) ** 2)))
    tail = np.concatenate(
        ([0.0], np.cumsum(((reference[n - 2 * max_lag - 1 :] - mu_r) ** 2)[::-1]))
    )
    total = reference_energy(reference, 0, n)
    energy = total - head[max_lag + lags] - tail[max_lag - lags]
    scores = fixed / np.sqrt(energy)

    def overlap_direct(m: int) -> float:
        return direct_correlation(reference, simulated, m, max(0, -m), min(n, n - m))

    def fixed_direct(m: int) -> float:
        c = direct_correlation(reference, simulated, m, max_lag, n - max_lag)
        return c / math.sqrt(reference_energy(reference, max_lag + m, n - max_lag + m))

    overlap_lag, overlap_margin = _best_lag(overlap, max_lag, overlap_direct)
    library_lag, library_margin = _best_lag(scores, max_lag, fixed_direct)
    result = Exactness(found, overlap_lag, overlap_margin, library_lag, library_margin)
    if n <= library_max:
        result.library_fft_lag = library_exact_lag(reference, simulated, max_lag)
    return result


def library_exact_lag(reference: FloatArray, simulated: FloatArray, max_lag: int) -> int | None:
    """The lag by the library's own exact FFT search, used by it for records ≤ 2^18 samples.

    The pyramid for long records must agree with it; calling the exact path on the long record
    shows whether it does. Private API: skipped if its shape changed.
    """
    from pytest_hevval.core import lag as lag_module

    exact = getattr(lag_module, "_fft_search", None)
    if exact is None:
        return None
    capped = min(max_lag, reference.shape[0] // 4)
    try:
        return int(
            exact(
                reference,
                simulated,
                capped,
                float(np.mean(reference)),
                float(np.mean(simulated)),
                1.0,
            )
        )
    except TypeError:
        return None


# --- Timing and memory -------------------------------------------------------------------------


def timed(fn: Callable[..., object], *args: Any) -> float:
    start = time.perf_counter()
    fn(*args)
    return time.perf_counter() - start


def timed_result(fn: Callable[..., dict[str, float]], *args: Any) -> tuple[float, dict[str, float]]:
    start = time.perf_counter()
    result = fn(*args)
    return time.perf_counter() - start, result


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return -1


def _reset_peak() -> bool:
    """Reset VmHWM to the current RSS (Linux ≥ 4.0); False where that is not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as clear:
            clear.write("5")
    except OSError:
        return False
    return True


def child_run(what: str, paths: tuple[str, str], max_lag_s: float, traced: bool) -> dict[str, Any]:
    """Run once in this fresh process: seconds, result, peak RSS growth, tracemalloc's peak."""
    reference, simulated = load_pair((Path(paths[0]), Path(paths[1])))
    candidates: dict[str, Callable[[FloatArray, FloatArray, float], Any]] = {
        "ours": ours,
        "straightforward": straightforward,
        "floor": lambda r, s, _: floor(r, s),
    }
    work = candidates[what]
    # Import-time and first-call allocations are not the algorithm's: warm up on a short slice.
    short = 1 << 19
    work(reference[:short].copy(), simulated[:short].copy(), max_lag_s)
    gc.collect()
    baseline = _status_kib("VmRSS")
    reset = _reset_peak()
    start = time.perf_counter()
    result = work(reference, simulated, max_lag_s)
    seconds = time.perf_counter() - start
    peak = _status_kib("VmHWM")
    report: dict[str, Any] = {
        "seconds": seconds,
        "result": result,
        "rss_growth_bytes": (peak - baseline) * 1024,
        "hwm_reset": reset,
    }
    if traced:
        del result
        gc.collect()
        tracemalloc.start()
        work(reference, simulated, max_lag_s)
        report["traced_peak_bytes"] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return report


def in_child(what: str, paths: tuple[Path, Path], max_lag_s: float, traced: bool) -> dict[str, Any]:
    """:func:`child_run` in a fresh interpreter; an out-of-memory kill is reported, not fatal."""
    command = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        what,
        str(paths[0]),
        str(paths[1]),
        "--max-lag-s",
        str(max_lag_s),
    ]
    if traced:
        command.append("--child-traced")
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode < 0:
        return {"error": f"killed by signal {-done.returncode} (out of memory when 9)"}
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr else "failed"}
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


# --- Machine facts -----------------------------------------------------------------------------


def machine_facts() -> dict[str, Any]:
    facts: dict[str, Any] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "cpus": os.cpu_count(),
        "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE", "(unset)"),
        "OPENBLAS_L2_SIZE": os.environ.get("OPENBLAS_L2_SIZE", "(unset)"),
    }
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as cpuinfo:
        for line in cpuinfo:
            if line.startswith("model name"):
                facts["cpu"] = line.split(":", 1)[1].strip()
                break
    try:
        from threadpoolctl import threadpool_info  # type: ignore[import-untyped]

        facts["blas"] = [
            {k: info.get(k) for k in ("internal_api", "version", "architecture", "num_threads")}
            for info in threadpool_info()
        ]
    except ImportError:
        facts["blas"] = "threadpoolctl not installed"
    return facts


def load_now() -> str:
    """Load average and CPU pressure: the machine is shared, so every table says how busy."""
    parts = []
    with contextlib.suppress(OSError):
        parts.append("load " + " ".join(os.getloadavg().__repr__().strip("()").split(", ")))
    with contextlib.suppress(OSError), open("/proc/pressure/cpu") as pressure:
        some = pressure.readline().split()
        parts.append("cpu pressure " + " ".join(some[1:3]))
    return "; ".join(parts)


# --- The comparisons ---------------------------------------------------------------------------


def _fmt_s(seconds: float) -> str:
    return f"{seconds * 1e3:9.1f} ms" if seconds < 10 else f"{seconds:9.2f} s "


def _fmt_mem(result: dict[str, Any], n: int) -> str:
    if "error" in result:
        return f"failed: {result['error'][:60]}"
    rss = result["rss_growth_bytes"]
    array = 8 * n
    text = f"RSS +{rss / 2**20:8.1f} MiB ({rss / array:5.2f} arrays)"
    if "traced_peak_bytes" in result:
        traced = result["traced_peak_bytes"]
        text += f", traced peak {traced / 2**20:8.1f} MiB ({traced / array:5.2f} arrays)"
    return text


def agree(a: dict[str, float], b: dict[str, float]) -> list[str]:
    """Fields where our result differs from the straightforward one beyond float rounding."""
    mismatches = []
    for key in ("mae", "rms", "error_std", "lambda1", "lambda2", "range"):
        if not math.isclose(a[key], b[key], rel_tol=1e-9, abs_tol=1e-12):
            mismatches.append(f"{key}: {a[key]!r} vs {b[key]!r}")
    return mismatches


@contextlib.contextmanager
def section(title: str) -> Iterator[None]:
    print(f"\n== {title} ==  [{load_now()}]", flush=True)
    yield


def _line(label: str, times: list[float]) -> str:
    return f"  {label:31s} min {_fmt_s(min(times))}   median {_fmt_s(statistics.median(times))}"


def _ratio_line(label: str, ratios: list[float]) -> str:
    return (
        f"  {label:31s} min {min(ratios):7.2f}x    median {statistics.median(ratios):7.2f}x"
        f"    ({len(ratios)} repetitions)"
    )


def run_size(kind: str, n: int, args: argparse.Namespace, report: dict[str, Any]) -> None:
    paths = cached_pair(kind, n, args.cache_dir)
    reference, simulated = load_pair(paths)
    lag_s = args.max_lag_s
    run_plain = args.straightforward == "yes" or (
        args.straightforward == "auto" and n <= args.straightforward_max
    )
    with section(f"{kind}: n = {n:.3g} samples, ±{lag_s:g} s lag window"):
        ours(reference[: 1 << 19], simulated[: 1 << 19], lag_s)  # warm-up
        rows: dict[str, list[float]] = {"floor": [], "ours": [], "straightforward": []}
        cpu_rows: dict[str, list[float]] = {"floor": [], "ours": []}
        result: dict[str, float] = {}
        plain: dict[str, float] = {}
        plain_runs: list[dict[str, Any]] = []
        for rep in range(args.repeat):
            cpu = time.process_time()
            rows["floor"].append(timed(floor, reference, simulated))
            cpu_rows["floor"].append(time.process_time() - cpu)
            cpu = time.process_time()
            seconds, result = timed_result(ours, reference, simulated, lag_s)
            cpu_rows["ours"].append(time.process_time() - cpu)
            rows["ours"].append(seconds)
            if run_plain and rep < args.straightforward_repeat:
                # In a child process: at 10^8 samples it needs about 17 arrays' worth of
                # memory, and an out-of-memory kill must not end the whole benchmark.
                run = in_child("straightforward", paths, lag_s, traced=n <= 10_000_000)
                plain_runs.append(run)
                if "error" in run:
                    print(f"  straightforward composition: {run['error']}")
                    run_plain = False
                else:
                    rows["straightforward"].append(run["seconds"])
                    plain = run["result"]
            gc.collect()
        ratios = [o / f for o, f in zip(rows["ours"], rows["floor"], strict=True)]
        entry: dict[str, Any] = {
            "signal": kind,
            "n": n,
            "times_s": rows,
            "ours_over_floor": ratios,
            "load": load_now(),
        }
        print(_line("floor (ref.sum(); sim.sum())", rows["floor"]))
        print(_line("signal_characteristics", rows["ours"]))
        print(_ratio_line("ours / floor, per repetition", ratios))
        best = min(rows["ours"]) / min(rows["floor"])
        entry["ours_min_over_floor_min"] = best
        print(f"  {'ours / floor, of the minima':31s} {best:7.2f}x")
        # CPU time (all threads) does not count the time a busy machine keeps us waiting.
        cpu_ratio = min(cpu_rows["ours"]) / min(cpu_rows["floor"])
        entry["cpu_s"] = cpu_rows
        entry["ours_cpu_over_floor_cpu"] = cpu_ratio
        print(
            f"  {'CPU seconds, minima':31s} floor {_fmt_s(min(cpu_rows['floor']))}"
            f"   ours {_fmt_s(min(cpu_rows['ours']))}   ratio {cpu_ratio:6.2f}x"
        )
        if rows["straightforward"]:
            k = len(rows["straightforward"])
            pair = [s / o for s, o in zip(rows["straightforward"], rows["ours"][:k], strict=True)]
            entry["straightforward_over_ours"] = pair
            mismatches = agree(result, plain)
            entry["straightforward_mismatches"] = mismatches
            print(_line("straightforward (scipy + numpy)", rows["straightforward"]))
            print(_ratio_line("straightforward / ours", pair))
            verdict = "yes" if not mismatches else "NO: " + "; ".join(mismatches)
            print(f"  same λ1–λ6 inputs within 1e-9: {verdict}; its lag {plain['lag']}")
        elif args.straightforward == "no":
            print("  straightforward composition: not run (--straightforward no)")
        elif not plain_runs:
            limit = args.straightforward_max
            print(f"  straightforward composition: not run (n > --straightforward-max {limit:.3g})")
        print(f"  lag found: {result['lag']} samples (simulation delayed {DELAYS[kind]} samples)")
        if args.exactness:
            exact = check_exactness(
                reference, simulated, lag_s, int(result["lag"]), args.library_exact_max
            )
            entry["exactness"] = exact.__dict__ | {"equal": exact.equal}
            verdict = "equal" if exact.equal else "DIFFERENT"
            print(
                f"  exact argmax, the library's definition (fixed window, normalised):"
                f" {exact.library_lag} -> {verdict} (runner-up {exact.library_margin:.1e} below)"
            )
            if exact.library_fft_lag is not None:
                same = "equal" if exact.library_fft_lag == result["lag"] else "DIFFERENT"
                fft_lag = exact.library_fft_lag
                print(f"  the library's exact FFT path on the whole record: {fft_lag} -> {same}")
            gap = exact.overlap_lag - int(result["lag"])
            print(
                "  exact argmax of the classical whole-overlap correlation:"
                f" {exact.overlap_lag} ({gap:+d}; runner-up {exact.overlap_margin:.1e} below)"
            )
        del reference, simulated
        gc.collect()
        if args.memory:
            entry["memory"] = {}
            for what in ("floor", "ours"):
                mem = in_child(what, paths, lag_s, traced=True)
                mem.pop("result", None)
                entry["memory"][what] = mem
                print(f"  peak extra memory, {what:15s}: {_fmt_mem(mem, n)}")
            if plain_runs:
                mem = dict(plain_runs[0])
                mem.pop("result", None)
                entry["memory"]["straightforward"] = mem
                print(f"  peak extra memory, {'straightforward':15s}: {_fmt_mem(mem, n)}")
        report["runs"].append(entry)


def run_iso(sizes: list[int], args: argparse.Namespace, report: dict[str, Any]) -> None:
    from objective_rating_metrics.rating import ISO18571

    def iso(ref2: FloatArray, sim2: FloatArray) -> dict[str, float]:
        return {"rating": float(ISO18571(ref2, sim2, dt=DT).overall_rating())}

    with section("ISO/TS 18571 (objective-rating-metrics) beside ours, drive signal"):
        # Its dynamic time warping is compiled by numba on first use: keep that out of the figures.
        warm_ref, warm_sim = make_pair("drive", 64)
        t = np.arange(64) * DT
        t_jit, _ = timed_result(iso, np.column_stack((t, warm_ref)), np.column_stack((t, warm_sim)))
        print(f"  first call (numba compilation, not counted): {_fmt_s(t_jit)}")
        for n in sizes:
            reference, simulated = make_pair("drive", n)
            t = np.arange(n) * DT
            ref2 = np.column_stack((t, reference))
            sim2 = np.column_stack((t, simulated))
            t_floor = min(timed(floor, reference, simulated) for _ in range(3))
            t_ours = min(timed(ours, reference, simulated, args.max_lag_s) for _ in range(3))
            t_iso, rating = timed_result(iso, ref2, sim2)
            report["iso"].append(
                {"n": n, "floor_s": t_floor, "ours_s": t_ours, "iso_s": t_iso} | rating
            )
            print(
                f"  n = {n:8d}: ISO 18571 {_fmt_s(t_iso)} (rating {rating['rating']:.3f})"
                f"   ours {_fmt_s(t_ours)}   ISO/ours {t_iso / t_ours:8.0f}x"
            )


class _Config:
    def getoption(self, name: str) -> bool:
        return False


class _Node:
    name = "bench"
    cls = None


class _Request:
    config = _Config()
    node = _Node()


def _num_check(fixture: Any, data: FloatArray, expected: Path, tolerance: dict[str, float]) -> None:
    fixture.check({"speed": data}, fullpath=expected, default_tolerance=tolerance)


def run_regressions(sizes: list[int], args: argparse.Namespace, report: dict[str, Any]) -> None:
    from pytest_regressions.num_regression import NumericRegressionFixture

    with section("pytest-regressions num_regression comparison step beside ours, drive signal"):
        for n in sizes:
            reference, simulated = make_pair("drive", n)
            # Wide enough to pass: this times the mechanics, not the building of a failure report.
            tolerance = {"atol": float(reference.max() - reference.min()), "rtol": 0.0}
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(tmp)
                fixture = NumericRegressionFixture(folder, folder, _Request())  # type: ignore[arg-type]
                expected = folder / "speed.csv"
                with contextlib.suppress(BaseException):  # the first call records, then fails
                    fixture.check({"speed": reference.copy()}, fullpath=expected)

                t_check = min(
                    timed(_num_check, fixture, simulated.copy(), expected, tolerance)
                    for _ in range(2)
                )
                obtained = next(folder.glob("*.obtained.csv"))
                t_compare = min(timed(fixture._check_fn, obtained, expected) for _ in range(2))
            t_ours = min(timed(ours, reference, simulated, args.max_lag_s) for _ in range(3))
            report["num_regression"].append(
                {"n": n, "check_s": t_check, "compare_s": t_compare, "ours_s": t_ours}
            )
            print(
                f"  n = {n:9d}: check() {_fmt_s(t_check)} (reading + comparing {_fmt_s(t_compare)})"
                f"   ours {_fmt_s(t_ours)}   check/ours {t_check / t_ours:6.0f}x"
            )


def _stage_times(
    reference: FloatArray, simulated: FloatArray, workers: int, args: argparse.Namespace
) -> dict[str, tuple[float, float]]:
    """Minimum (CPU, wall) seconds of each stage over ``args.repeat`` interleaved rounds."""
    from pytest_hevval.core import characteristics as core
    from pytest_hevval.core import lag as lag_module

    n = reference.shape[0]
    max_lag = round(args.max_lag_s / DT)
    levels = core._level_buffers(n, DT, args.max_lag_s)
    sums = core._all_sums(reference, simulated, 1.0, workers, levels)
    means = {"ref_mean": sums.ref_sum / n, "sim_mean": sums.sim_sum / n}
    stages: dict[str, Callable[[], object]] = {
        "floor": lambda: floor(reference, simulated),
        "main pass (λ1–λ6 sums, levels 1–3)": lambda: core._all_sums(
            reference, simulated, 1.0, workers, levels
        ),
        "lag search from those levels": lambda: lag_module._search(
            reference, simulated, max_lag, scale=1.0, workers=workers, levels=levels or [], **means
        ),
        "signal_characteristics": lambda: signal_characteristics(
            reference, simulated, dt=DT, max_lag_s=args.max_lag_s, workers=workers
        ),
    }
    best: dict[str, tuple[float, float]] = {}
    for _ in range(args.repeat):
        for name, fn in stages.items():
            cpu = time.process_time()
            wall = time.perf_counter()
            fn()
            wall = time.perf_counter() - wall
            cpu = time.process_time() - cpu
            old = best.get(name, (math.inf, math.inf))
            best[name] = (min(old[0], cpu), min(old[1], wall))
    return best


def run_stages(n: int, args: argparse.Namespace, report: dict[str, Any]) -> None:
    """CPU and wall time of each stage of ours, on 1 and 2 threads: where the time goes.

    Uses private functions of the core (the main pass and the lag search), so it may need
    updating when their internals change.
    """
    reference, simulated = load_pair(cached_pair("noise", n, args.cache_dir))
    with section(f"stages of ours, noise signal, n = {n:.3g}; minimum of {args.repeat}"):
        ours(reference[: 1 << 19], simulated[: 1 << 19], args.max_lag_s)
        for workers in (1, 2):
            for name, (cpu, wall) in _stage_times(reference, simulated, workers, args).items():
                print(
                    f"  {workers} thread{'s' if workers > 1 else ' '} {name:36s}"
                    f" CPU {cpu / n * 1e9:6.2f} ns/sample   wall {wall / n * 1e9:6.2f} ns/sample"
                )
                report["stages"].append(
                    {"n": n, "workers": workers, "stage": name, "cpu_s": cpu, "wall_s": wall}
                )


def run_paths(n: int, args: argparse.Namespace, report: dict[str, Any]) -> None:
    """The numpy path and the compiled kernel side by side with the floor, on 2 threads.

    Rounds are interleaved (floor, numpy, kernel, floor, …) so that a neighbour's load falls
    on all three alike; then each path's stages show where the remaining time goes.
    """
    from pytest_hevval.core import kernel

    reference, simulated = load_pair(cached_pair("noise", n, args.cache_dir))
    os.environ[kernel.KERNEL_ENV] = "numba"
    compile_s = timed(ours, reference[: 1 << 19], simulated[: 1 << 19], args.max_lag_s)
    print(f"  first kernel call (compile or load from cache): {_fmt_s(compile_s)}")
    paths = ("numpy", "numba")
    rows: dict[str, list[float]] = {"floor": [], "numpy": [], "numba": []}
    results: dict[str, dict[str, float]] = {}
    with section(f"paths, noise signal, n = {n:.3g}, 2 threads; {args.repeat} interleaved rounds"):
        for _ in range(args.repeat):
            rows["floor"].append(timed(floor, reference, simulated))
            for path in paths:
                os.environ[kernel.KERNEL_ENV] = path
                seconds, results[path] = timed_result(ours, reference, simulated, args.max_lag_s)
                rows[path].append(seconds)
        for name, times in rows.items():
            print(_line(name, times))
        for path in paths:
            ratio = min(rows[path]) / min(rows["floor"])
            print(f"  {path + ' / floor, of the minima':31s} {ratio:7.2f}x")
        mismatches = agree(results["numpy"], results["numba"])
        print(f"  numpy and kernel agree: {mismatches or 'yes'}")
        entry: dict[str, Any] = {"n": n, "compile_s": compile_s, **rows, "agree": not mismatches}
        for path in paths:
            os.environ[kernel.KERNEL_ENV] = path
            stages = _stage_times(reference, simulated, 2, args)
            entry[f"{path}_stages"] = stages
            for name, (cpu, wall) in stages.items():
                print(f"  {path:5s} {name:36s} CPU {_fmt_s(cpu)}   wall {_fmt_s(wall)}")
        report["paths"].append(entry)
    os.environ.pop(kernel.KERNEL_ENV, None)


def _count(text: str) -> int:
    return int(float(text))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--samples", type=_count, nargs="+", default=[2_000_000], help="record lengths (1e8 works)"
    )
    parser.add_argument("--signals", nargs="+", choices=SIGNALS, default=list(SIGNALS))
    parser.add_argument("--max-lag-s", type=float, default=10.0, help="lag window half-width, s")
    parser.add_argument("--repeat", type=int, default=5, help="repetitions of floor and ours")
    parser.add_argument("--straightforward", choices=("auto", "yes", "no"), default="auto")
    parser.add_argument(
        "--straightforward-max",
        type=_count,
        default=100_000_000,
        help="largest n for it under auto",
    )
    parser.add_argument("--straightforward-repeat", type=int, default=2)
    parser.add_argument("--no-memory", dest="memory", action="store_false")
    parser.add_argument("--no-exactness", dest="exactness", action="store_false")
    parser.add_argument(
        "--library-exact-max",
        type=_count,
        default=10_000_000,
        help="largest n for the library's exact FFT search",
    )
    parser.add_argument("--iso-samples", type=_count, nargs="*", default=[1000, 4000])
    parser.add_argument(
        "--regression-samples", type=_count, nargs="*", default=[100_000, 1_000_000]
    )
    parser.add_argument(
        "--cache-dir", type=Path, default=Path(tempfile.gettempdir()) / "hevval-bench"
    )
    parser.add_argument("--json", type=Path, help="also write every figure here")
    parser.add_argument(
        "--stages", action="store_true", help="only the per-stage CPU/wall breakdown of ours"
    )
    parser.add_argument(
        "--paths",
        action="store_true",
        help="only the numpy path against the compiled kernel (needs the fast extra)",
    )
    parser.add_argument("--child", nargs=3, metavar=("WHAT", "REF", "SIM"), help=argparse.SUPPRESS)
    parser.add_argument("--child-traced", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        what, ref_path, sim_path = args.child
        traced = args.child_traced
        print(json.dumps(child_run(what, (ref_path, sim_path), args.max_lag_s, traced)))
        return 0

    report: dict[str, Any] = {
        "command": " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]),
        "machine": machine_facts(),
        "runs": [],
        "iso": [],
        "num_regression": [],
    }
    print("machine:", json.dumps(report["machine"]))
    for part, run_part in (("paths", run_paths), ("stages", run_stages)):
        if getattr(args, part):
            report[part] = []
            for n in args.samples:
                run_part(n, args, report)
            if args.json:
                args.json.write_text(json.dumps(report, indent=2, default=str))
            return 0
    for n in args.samples:
        for kind in args.signals:
            run_size(kind, n, args, report)
    if args.iso_samples:
        run_iso(args.iso_samples, args, report)
    if args.regression_samples:
        run_regressions(args.regression_samples, args, report)
    if args.json:
        args.json.write_text(json.dumps(report, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
