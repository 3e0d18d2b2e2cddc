"""Synthetic but plausible spec results, for testing and benchmarking the reports.

A made-up hybrid-vehicle trip: a speed profile, and from it motor torque, battery power,
current and voltage, state of charge and engine speed. The "simulated" traces are the measured
ones with typical model faults (lag, gain error, bias, missed spikes, noise). The traces are
written to files and scored by the real pipeline
(:func:`pytest_hevval.scoring.run.run_specs`), so every
number on a demo report — λ1–λ7, Φ, the gates, where each error appears — is computed exactly as
on a real one. Only the history trend and the diagnosis shown beside a signal are made up.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import yaml

from pytest_hevval.scoring.engine import Evaluation
from pytest_hevval.scoring.run import RunOptions, run_specs
from pytest_hevval.spec.load import load_spec

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


def _signal_tree(prefix: str) -> dict[str, Any]:
    """The spec's YAML for one set: columns are named ``<prefix><path>``."""
    nodes: dict[str, dict[str, Any]] = {}
    root: dict[str, Any] = {}
    for path, unit, alpha, thresholds in _TREE:
        name = path.rsplit("/", 1)[-1]
        column = prefix + path.replace("/", ".")
        node: dict[str, Any] = {
            "signal": name if "/" in path else prefix.rstrip("_") or name,
            "ref": column,
            "sim": column,
            "unit": unit,
            "alpha": alpha,
            "thresholds": dict(thresholds),
        }
        nodes[path] = node
        if "/" in path:
            nodes[path.rsplit("/", 1)[0]].setdefault("children", []).append(node)
        else:
            root = node
    return root


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
    dt = 1.0 / rate_hz
    n = max(16, round(duration_s * rate_hz))
    t = np.arange(n, dtype=np.float64) * dt
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="hevval-demo-") as folder:
        root = Path(folder)
        for spec_index in range(specs):
            measured: dict[str, FloatArray] = {"time": t}
            simulated: dict[str, FloatArray] = {"time": t}
            sets = []
            for set_index in range(1, sets_per_spec + 1):
                # Alternate a poor model and a good one, so a demo shows both verdicts.
                traces = _traces(t, rng, 1.0 if spec_index % 2 == 0 else 0.35)
                prefix = "" if sets_per_spec == 1 else f"set{set_index}_"
                for path, (ref, sim) in traces.items():
                    measured[prefix + path.replace("/", ".")] = ref
                    simulated[prefix + path.replace("/", ".")] = sim
                sets.append(_signal_tree(prefix))
            stem = f"demo_trip_{spec_index + 1:02d}"
            pd.DataFrame(measured).to_csv(root / f"{stem}_measured.csv", index=False)
            pd.DataFrame(simulated).to_csv(root / f"{stem}_model.csv", index=False)
            letter = chr(ord("A") + spec_index % 26)
            spec_text = {
                "name": f"demo trip {letter}{spec_index // 26 + 1:02d}",
                "reference": {"path": f"{stem}_measured.csv", "time": "time"},
                "model": {"path": f"{stem}_model.csv", "time": "time"},
                "alignment": {"max_lag_s": 5.0},
                "min_phi": 0.95 if spec_index % 2 == 0 else 0.93,
                "sets": sets,
            }
            spec_path = root / f"{stem}.hevval.yaml"
            spec_path.write_text(yaml.safe_dump(spec_text, sort_keys=False), "utf-8")
            (outcome,) = run_specs([load_spec(spec_path)], RunOptions(rootdir=root, figures=True))
            assert isinstance(outcome, Evaluation), outcome
            result = outcome.result.to_dict()
            result["spec"] = f"specs/{stem}.hevval.yaml"
            _decorate(result, rng, history=history, diagnosis=diagnosis)
            out.append(result)
    return out


def _decorate(
    result: dict[str, Any], rng: np.random.Generator, *, history: bool, diagnosis: bool
) -> None:
    """The made-up parts: a diagnosis beside each failing signal, a trend beside three."""
    for signal in result["signals"]:
        signal["diagnosis"] = (
            _diagnosis(signal, rng) if diagnosis and not signal["passed"] else None
        )
        signal["history"] = None
    if not history:
        return
    phi = result["phi"]
    for signal in result["signals"][:3]:
        signal["history"] = [
            {
                "version": f"v{k + 1}",
                "phi": round(phi - 0.02 * (4 - k) * rng.random(), 4),
                "lambdas": _older(signal["lambdas"], 0.03 * (4 - k), rng),
            }
            for k in range(5)
        ]


def _older(lambdas: Any, drop: float, rng: np.random.Generator) -> Any:
    """The same characteristics as they might have been some versions ago."""
    if isinstance(lambdas, dict):
        return {k: round(max(0.0, v - drop * rng.random()), 4) for k, v in lambdas.items()}
    return [round(max(0.0, v - drop * rng.random()), 4) for v in lambdas]


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
