"""Synthetic but plausible spec results, for trying out and testing the reports.

A made-up hybrid-vehicle trip: a speed profile, and from it motor torque, battery power,
current and voltage, state of charge and engine speed. The "simulated" traces are the measured
ones with typical model faults (lag, gain error, bias, missed spikes, noise), scored with the
real characteristics of :mod:`pytest_hevval.core.characteristics`, so every number on a demo
report means what it would on a real one.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.characteristics import signal_characteristics
from ..core.registry import FUSED_CHARACTERISTICS, PAPER_CHARACTERISTICS
from ..result import RESULT_SCHEMA_VERSION
from .figures import figure_data

__all__ = ["demo_results"]

FloatArray = npt.NDArray[np.float64]

# (path, unit, alpha, thresholds) of one signal set; the tree comes from the paths.
_TREE: tuple[tuple[str, str, float, dict[str, float]], ...] = (
    ("v", "km/h", 1.0, {"lag_correlation": 0.95, "mae": 0.95}),
    ("v/T_mot", "Nm", 0.7, {"lag_correlation": 0.9, "mae": 0.9, "derivative_match": 0.6}),
    ("v/T_mot/N_eng", "rpm", 0.5, {"mae": 0.985}),
    ("v/P_batt", "kW", 0.7, {"mae": 0.9, "rms": 0.88, "emergent": 0.9}),
    ("v/P_batt/I_batt", "A", 0.5, {"mae": 0.9, "anomaly": 0.95}),
    ("v/P_batt/U_batt", "V", 0.5, {"mae": 0.9}),
    ("v/P_batt/SoC", "%", 0.5, {"error_std": 0.9}),
)


def _speed(t: FloatArray, rng: np.random.Generator) -> FloatArray:
    """A stop-and-go profile: smoothed random target speeds with standstills."""
    n = t.shape[0]
    knots = max(4, int(t[-1] - t[0]) // 40 + 2)
    targets = rng.uniform(0.0, 90.0, knots)
    targets[rng.random(knots) < 0.25] = 0.0
    profile = np.interp(np.linspace(0, knots - 1, n), np.arange(knots), targets)
    width = max(3, n // (knots * 3))
    kernel = np.ones(width) / width
    smooth: FloatArray = np.convolve(np.pad(profile, width, mode="edge"), kernel, "same")[
        width:-width
    ]
    return np.clip(smooth, 0.0, None)


def _traces(
    t: FloatArray, rng: np.random.Generator, severity: float
) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Measured and simulated traces; ``severity`` scales every model fault (0 = perfect)."""
    dt = float(t[1] - t[0])
    v_true = _speed(t, rng)
    v = np.clip(v_true + rng.normal(0.0, 0.1, t.shape[0]), 0.0, None)
    accel = np.gradient(v_true / 3.6, dt)
    torque = 900.0 * accel + 0.02 * v_true**1.5 + rng.normal(0.0, 2.0, t.shape[0])
    power = torque * v / 3.6 * 0.35 / 10.0
    spikes = np.zeros_like(t)
    spike_at = rng.choice(t.shape[0], size=max(3, t.shape[0] // 400), replace=False)
    spikes[spike_at] = rng.normal(0.0, 150.0, spike_at.shape[0])
    current = power * 1000.0 / 360.0 + spikes
    voltage = 370.0 - 0.08 * current + rng.normal(0.0, 0.6, t.shape[0])
    soc = 70.0 - np.cumsum(power) * dt / 3600.0 / 20.0 * 100.0
    n_eng = np.where(v > 40.0, 1100.0 + 28.0 * v, 800.0) + rng.normal(0.0, 15.0, t.shape[0])

    def lagged(x: FloatArray, seconds: float) -> FloatArray:
        shift = round(seconds / dt)
        return np.concatenate([np.full(shift, x[0]), x[: x.shape[0] - shift]]) if shift else x

    noise = rng.normal(0.0, 1.0, t.shape[0]) * severity
    k = severity
    return {
        "v": (v, lagged(v, 0.2 * k) * (1 + 0.01 * k) + 0.2 * noise),
        "v/T_mot": (torque, lagged(torque, 0.3 * k) * (1 - 0.07 * k) + 6.0 * noise),
        "v/T_mot/N_eng": (n_eng, np.where(v > 40.0 + 2 * k, 1100.0 + (28 + 0.5 * k) * v, 800.0)),
        "v/P_batt": (power, lagged(power, 0.1 * k) * (1 - 0.1 * k) + 0.8 * k),
        "v/P_batt/I_batt": (current, current - spikes * min(1.0, k) + 3.0 * noise),
        "v/P_batt/U_batt": (voltage, voltage + 0.9 * k + 0.3 * noise),
        "v/P_batt/SoC": (soc, soc + np.linspace(0.0, 1.2 * k, t.shape[0])),
    }


def _mean_own(values: dict[str, float]) -> float:
    return sum(values[name] for name in FUSED_CHARACTERISTICS) / 6.0


def _emergent(own: dict[str, float], children: list[dict[str, float]]) -> float:
    if not children:
        return 1.0
    child_mean = sum(_mean_own(c) for c in children) / len(children)
    return max(0.0, min(1.0, 1.0 - abs(_mean_own(own) - child_mean)))


def demo_results(
    *,
    specs: int = 2,
    sets_per_spec: int = 1,
    duration_s: float = 600.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    history: bool = True,
    diagnosis: bool = True,
) -> list[dict[str, Any]]:
    """Spec result dicts (the report's input) for ``specs`` synthetic trips.

    Each spec holds ``sets_per_spec`` signal sets of seven signals each.
    """
    rng = np.random.default_rng(seed)
    out: list[dict[str, Any]] = []
    dt = 1.0 / rate_hz
    n = max(16, round(duration_s * rate_hz))
    t = np.arange(n, dtype=np.float64) * dt
    for spec_index in range(specs):
        signals: list[dict[str, Any]] = []
        for set_index in range(1, sets_per_spec + 1):
            # Alternate a poor model and a good one, so a demo shows both verdicts.
            traces = _traces(t, rng, 1.0 if spec_index % 2 == 0 else 0.35)
            prefix = "" if sets_per_spec == 1 else f"set{set_index}:"
            level_counts: dict[int, int] = {}
            raw: dict[str, dict[str, float]] = {}
            for path, unit, alpha, thresholds in _TREE:
                ref, sim = traces[path]
                level = path.count("/") + 1
                level_counts[level] = level_counts.get(level, 0) + 1
                chars = signal_characteristics(ref, sim, dt=dt, max_lag_s=5.0)
                raw[path] = chars.values
                signals.append(
                    {
                        "path": prefix + path,
                        "name": path.rsplit("/", 1)[-1],
                        "set": set_index,
                        "level": level,
                        "position": level_counts[level],
                        "alpha": alpha,
                        "line": 6 + 5 * len(signals),
                        "unit": unit,
                        "thresholds": dict(thresholds),
                        **{k: v for k, v in chars.as_dict().items() if k != "lambdas"},
                        "figures": figure_data(
                            ref, sim, dt=dt, start_s=0.0, max_lag=round(5.0 / dt)
                        ),
                    }
                )
            # λ7 bottom-up, then gates and the origin of each error.
            by_path = {s["path"]: s for s in signals[-len(_TREE) :]}
            for path, *_ in reversed(_TREE):
                kids = [
                    by_path[prefix + p]["lambdas"]
                    for p, *_ in _TREE
                    if p.rsplit("/", 1)[0] == path and "/" in p
                ]
                own = raw[path]
                by_path[prefix + path]["lambdas"] = {**own, "emergent": _emergent(own, kids)}
        for s in signals:
            s["failures"] = [
                {
                    "characteristic": name,
                    "value": value,
                    "threshold": s["thresholds"][name],
                }
                for name, value in s["lambdas"].items()
                if name in s["thresholds"] and value < s["thresholds"][name]
            ]
            s["passed"] = not s["failures"]
        for s in signals:
            failing_below = [
                o["path"]
                for o in signals
                if o["path"].startswith(s["path"] + "/") and not o["passed"]
            ]
            own_fault = any(f["characteristic"] != "emergent" for f in s["failures"])
            s["origin"] = (not s["passed"]) and (own_fault or not failing_below)
            s["origins"] = (
                [] if s["passed"] else ([s["path"]] if s["origin"] else []) + failing_below
            )
            s["diagnosis"] = None
            s["history"] = None
        numerator = sum(s["alpha"] * sum(s["lambdas"].values()) for s in signals)
        denominator = sum(s["alpha"] * len(s["lambdas"]) for s in signals)
        phi = numerator / denominator
        min_phi = 0.95 if spec_index % 2 == 0 else 0.93
        if diagnosis:
            for s in signals:
                if not s["passed"]:
                    s["diagnosis"] = _diagnosis(s, rng)
        if history:
            for s in signals[:3]:
                s["history"] = [
                    {
                        "version": f"v{k + 1}",
                        "phi": round(phi - 0.02 * (4 - k) * rng.random(), 4),
                        "lambdas": {
                            name: round(max(0.0, v - 0.03 * (4 - k) * rng.random()), 4)
                            for name, v in s["lambdas"].items()
                        },
                    }
                    for k in range(5)
                ]
        out.append(
            {
                "schema_version": RESULT_SCHEMA_VERSION,
                "name": f"demo trip {chr(ord('A') + spec_index % 26)}{spec_index // 26 + 1:02d}",
                "spec": f"specs/demo_trip_{spec_index + 1:02d}.hevval.yaml",
                "spec_hash": hashlib.sha256(f"demo {spec_index} {seed}".encode()).hexdigest(),
                "phi": round(phi, 6),
                "min_phi": min_phi,
                "passed": phi >= min_phi and all(s["passed"] for s in signals),
                "weights": dict.fromkeys(PAPER_CHARACTERISTICS, 1.0),
                "alignment": {
                    "rate_hz": rate_hz,
                    "start_s": 0.0,
                    "stop_s": round(float(t[-1]), 6),
                    "n_samples": n,
                    "offset_s": 0.0,
                    "coverage": 1.0,
                },
                "signals": signals,
            }
        )
    return out


def _diagnosis(signal: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    worst = min(signal["failures"], key=lambda f: f["value"] - f["threshold"])
    candidates: list[dict[str, Any]] = [
        {"name": "lag(0.2 s)", "kind": "lag", "explained_fraction": 0.0, "coefficient": 0.2},
        {"name": "gain", "kind": "gain", "explained_fraction": 0.0, "coefficient": 0.93},
        {"name": "bias", "kind": "offset", "explained_fraction": 0.0, "coefficient": 0.8},
        {"name": "ambient_temp", "kind": "input", "explained_fraction": 0.0, "coefficient": 0.01},
    ]
    shares = rng.dirichlet([4.0, 2.0, 1.0, 0.3])
    for c, share in zip(candidates, shares, strict=True):
        c["explained_fraction"] = round(float(share) * 0.85, 4)
        c["significant"] = c["explained_fraction"] > 0.1
    candidates.sort(key=lambda c: -c["explained_fraction"])
    return {
        "summary": (
            f"{candidates[0]['name']} explains {candidates[0]['explained_fraction']:.0%} of the "
            f"residual; {worst['characteristic']} is {worst['value']:.3f} against "
            f"{worst['threshold']:.3f}."
        ),
        "candidates": candidates,
    }
