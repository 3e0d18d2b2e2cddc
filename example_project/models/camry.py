"""Fuel-flow model of a 2018 Toyota Camry 2.5 L on a chassis dynamometer, from speed alone.

The dynamometer reproduces a road load ``F = f0 + f2·v² + m·a`` at the wheels. The engine's
fuel flow follows a Willans line: a fixed idle flow plus a flow proportional to the positive
wheel power. (A further term proportional to speed, standing in for engine friction, fitted
to zero on the hot UDDS and was dropped.) When the wheels demand clearly negative power and
the car is moving, the engine control cuts the fuel.

The model knows nothing of engine temperature: it describes a warm engine.

Output columns: ``time`` (s), ``v`` (mph), ``fuel_rate`` (cm³/s), ``fuel_cum`` (cm³).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

__all__ = ["PARAMS_FILE", "CamryParams", "fuel_rate", "load_params", "simulate"]

FloatArray = npt.NDArray[np.float64]

PARAMS_FILE = Path(__file__).with_name("camry_params.json")

TIME = "Time[s]"
SPEED = "Dyno_Spd[mph]"
MPH = 0.44704


@dataclass(frozen=True)
class CamryParams:
    """Model parameters; the fitted ones default to starting guesses."""

    # Assumed, not fitted: a mid-size sedan's inertia class and typical road-load terms
    # (rolling resistance about 0.008, drag area about 0.63 m²). Fuel alone cannot separate
    # them from the engine efficiency.
    mass_kg: float = 1650.0
    road_load_f0_n: float = 130.0
    road_load_f2_n_per_m2s2: float = 0.38
    # Below this wheel power (W) a moving car runs on fuel cut-off.
    fuel_cut_power_w: float = -1000.0
    # Fitted by fit_camry.py.
    idle_flow_cc_s: float = 0.2
    flow_per_kw_cc_s: float = 0.1


FITTED = ("idle_flow_cc_s", "flow_per_kw_cc_s")


def load_params(path: Path | None = None) -> CamryParams:
    """The fitted parameters from ``camry_params.json``, or the defaults."""
    source = PARAMS_FILE if path is None else path
    if not source.exists():
        return CamryParams()
    values = json.loads(source.read_text(encoding="utf-8"))["params"]
    unknown = set(values) - {f.name for f in fields(CamryParams)}
    if unknown:
        raise ValueError(
            f"{source.name} sets unknown parameter(s) {sorted(unknown)}; "
            "delete it and rerun fit_camry.py"
        )
    return replace(CamryParams(), **{k: float(v) for k, v in values.items()})


def fuel_rate(time_s: FloatArray, speed_m_s: FloatArray, p: CamryParams) -> FloatArray:
    """Fuel flow (cm³/s) for a speed trace (m/s) sampled at ``time_s``."""
    accel = np.gradient(speed_m_s, time_s)
    force = p.road_load_f0_n + p.road_load_f2_n_per_m2s2 * speed_m_s**2 + p.mass_kg * accel
    power_kw = force * speed_m_s / 1e3
    moving = speed_m_s > 0.5
    driving = p.idle_flow_cc_s + p.flow_per_kw_cc_s * np.maximum(power_kw, 0.0)
    cut = moving & (power_kw * 1e3 < p.fuel_cut_power_w)
    return np.where(cut, 0.0, np.where(moving, driving, p.idle_flow_cc_s))


def simulate(
    reference: pd.DataFrame, *, params_file: str | None = None, **overrides: Any
) -> pd.DataFrame:
    """Simulate one dynamometer test from ``Time[s]`` and ``Dyno_Spd[mph]``."""
    known = {f.name for f in fields(CamryParams)}
    unknown = set(overrides) - known
    if unknown:
        raise TypeError(f"unknown Camry parameter(s) {sorted(unknown)}; known: {sorted(known)}")
    for name in (TIME, SPEED):
        if name not in reference.columns:
            raise KeyError(f"models.camry needs the reference channel {name!r} in model.inputs")
    p = load_params(None if params_file is None else Path(params_file))
    p = replace(p, **{k: float(v) for k, v in overrides.items()})
    time_s = reference[TIME].to_numpy(dtype=np.float64)
    speed_mph = reference[SPEED].to_numpy(dtype=np.float64)
    rate = fuel_rate(time_s, speed_mph * MPH, p)
    cumulative = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(time_s))))
    frame: pd.DataFrame = pd.DataFrame(
        {"time": time_s, "v": speed_mph, "fuel_rate": rate, "fuel_cum": cumulative}
    )
    return frame
