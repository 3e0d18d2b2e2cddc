"""Fit the Camry fuel model to one hot-start dynamometer test; write models/camry_params.json.

The residual holds the fuel rate and the cumulative fuel, each divided by its measured range,
so the fit follows the instantaneous flow without drifting on the total. Only the hot UDDS
(test 61811012) is read; HWFET, US06 and the FTP are kept for validation.

    python fit_camry.py
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.optimize import least_squares

from models.camry import FITTED, MPH, PARAMS_FILE, SPEED, TIME, CamryParams, fuel_rate

HERE = Path(__file__).resolve().parent
FIT_TEST = "61811012"
FUEL = "Eng_FuelFlow_Direct_DI[ccps]"


def cumulative(
    rate: npt.NDArray[np.float64], time_s: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    return np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(time_s))))


def main() -> None:
    test = pd.read_parquet(HERE / "data" / "camry" / f"{FIT_TEST}.parquet")
    time_s = test[TIME].to_numpy(dtype=np.float64)
    speed = test[SPEED].to_numpy(dtype=np.float64) * MPH
    measured = test[FUEL].to_numpy(dtype=np.float64)
    measured_cum = cumulative(measured, time_s)
    rate_scale = float(np.ptp(measured))
    cum_scale = float(np.ptp(measured_cum))

    def model(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        p = replace(CamryParams(), **dict(zip(FITTED, x.tolist(), strict=True)))
        return fuel_rate(time_s, speed, p)

    def residuals(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        rate = model(x)
        return np.concatenate(
            (
                (rate - measured) / rate_scale,
                (cumulative(rate, time_s) - measured_cum) / cum_scale,
            )
        )

    start = CamryParams()
    x0 = np.array([getattr(start, name) for name in FITTED])
    result = least_squares(residuals, x0, bounds=(0.0, np.inf))
    params = dict(zip(FITTED, result.x.tolist(), strict=True))
    rate = model(result.x)
    summary = {
        "rms_fuel_rate_cc_s": float(np.sqrt(np.mean((rate - measured) ** 2))),
        "fuel_measured_cc": float(measured_cum[-1]),
        "fuel_model_cc": float(cumulative(rate, time_s)[-1]),
    }
    PARAMS_FILE.write_text(
        json.dumps(
            {
                "note": "Written by fit_camry.py (scipy.optimize.least_squares on fuel rate "
                "and cumulative fuel). Parameters not listed keep the defaults in "
                "models/camry.py.",
                "fitted_on": f"data/camry/{FIT_TEST}.parquet (hot-start UDDS)",
                "params": {k: round(v, 6) for k, v in params.items()},
                "fit_trip": {k: round(v, 4) for k, v in summary.items()},
            },
            indent=2,
        )
        + "\n",
        encoding="utf-8",
    )
    for name, value in params.items():
        print(f"  {name:30s} {value:10.5g}")
    for name, value in summary.items():
        print(f"  {name:30s} {value:10.5g}")
    print(f"wrote {PARAMS_FILE.relative_to(HERE)}")


if __name__ == "__main__":
    main()
