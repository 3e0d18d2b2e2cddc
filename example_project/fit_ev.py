"""Fit the EV model's free parameters to one measured trip and store them in models/ev_params.json.

Each model version is fitted on its own: version 1, which knows no auxiliary load, has to
explain the same battery current with a larger constant base load than version 2. The other
trips in ``data/i3`` are kept for validation and are never read here.

    python fit_ev.py                  # fits both versions on TripA01
    python fit_ev.py --trip A02 --version 2
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.optimize import least_squares

from models.ev import FITTED, PARAMS_FILE, EVParams, simulate

HERE = Path(__file__).resolve().parent

# Measured channel compared with each simulated one; every residual is divided by the
# measured range so that amperes, volts, newton-metres and percent weigh alike.
TARGETS = {
    "I_batt": "Battery Current [A]",
    "U_batt": "Battery Voltage [V]",
    "T_mot": "Motor Torque [Nm]",
    "SoC": "SoC [%]",
}

INPUTS = {
    1: ["Time [s]", "Velocity [km/h]", "SoC [%]"],
    2: [
        "Time [s]",
        "Velocity [km/h]",
        "SoC [%]",
        "Elevation [m]",
        "Heating Power CAN [kW]",
        "AirCon Power [kW]",
    ],
}

BOUNDS = {
    "mass_kg": (1100.0, 2000.0),
    "rolling_resistance": (0.003, 0.03),
    "copper_loss_w_per_nm2": (0.0, 2.0),
    "power_loss_fraction": (0.0, 0.3),
    "base_load_w": (0.0, 5000.0),
    "ocv_at_0_soc_v": (250.0, 400.0),
    "ocv_per_soc_v": (0.0, 3.0),
    "internal_resistance_ohm": (0.01, 0.5),
    "capacity_ah": (40.0, 80.0),
}


def fit(trip: pd.DataFrame, version: int) -> tuple[dict[str, float], dict[str, float]]:
    """Least-squares fit; returns the parameters and the RMS error per target channel."""
    inputs = trip.loc[:, INPUTS[version]]
    measured = {sim: trip[col].to_numpy(dtype=np.float64) for sim, col in TARGETS.items()}
    scale = {sim: float(np.nanmax(m) - np.nanmin(m)) for sim, m in measured.items()}
    start = asdict(EVParams())
    x0 = np.array([start[name] for name in FITTED])
    lower = np.array([BOUNDS[name][0] for name in FITTED])
    upper = np.array([BOUNDS[name][1] for name in FITTED])
    # Solve in units of the bounds so that kilograms and ohms get comparable steps.
    span = upper - lower

    def residuals(z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        values = dict(zip(FITTED, lower + z * span, strict=True))
        sim = simulate(inputs, version=version, **values)
        parts = [
            np.nan_to_num((sim[name].to_numpy() - measured[name]) / scale[name]) for name in TARGETS
        ]
        return np.concatenate(parts)

    result = least_squares(
        residuals, (x0 - lower) / span, bounds=(0.0, 1.0), x_scale="jac", diff_step=1e-4
    )
    best = dict(zip(FITTED, (lower + result.x * span).tolist(), strict=True))
    sim = simulate(inputs, version=version, **best)
    rms = {
        name: float(np.sqrt(np.nanmean((sim[name].to_numpy() - measured[name]) ** 2)))
        for name in TARGETS
    }
    return best, rms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trip", default="A01", help="trip to fit on (default A01)")
    parser.add_argument("--version", type=int, choices=(1, 2), action="append")
    args = parser.parse_args()
    versions = args.version or [1, 2]
    trip = pd.read_parquet(HERE / "data" / "i3" / f"Trip{args.trip}.parquet")

    stored = json.loads(PARAMS_FILE.read_text(encoding="utf-8")) if PARAMS_FILE.exists() else {}
    stored.setdefault("versions", {})
    stored["note"] = (
        "Written by fit_ev.py (scipy.optimize.least_squares on battery current and voltage, "
        "motor torque and SoC, each divided by its measured range). Parameters not listed "
        "keep the defaults in models/ev.py."
    )
    for version in versions:
        began = time.perf_counter()
        params, rms = fit(trip, version)
        elapsed = time.perf_counter() - began
        check = replace(EVParams(), **params)
        stored["versions"][str(version)] = {
            "fitted_on": f"data/i3/Trip{args.trip}.parquet",
            "params": {k: round(v, 6) for k, v in asdict(check).items() if k in FITTED},
            "rms_error_on_fit_trip": {k: round(v, 4) for k, v in rms.items()},
        }
        print(f"version {version} fitted on Trip{args.trip} in {elapsed:.1f} s")
        for name, value in params.items():
            print(f"  {name:26s} {value:12.5g}")
        for name, value in rms.items():
            print(f"  RMS error {name:16s} {value:10.4g}")
    PARAMS_FILE.write_text(json.dumps(stored, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {PARAMS_FILE.relative_to(HERE)}")


if __name__ == "__main__":
    main()
