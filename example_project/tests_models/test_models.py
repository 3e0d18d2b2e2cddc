"""Checks of the example models themselves (run: ``pytest tests_models`` in example_project).

These guard the physics and the conventions the specs rely on; the validation against
measurements is the specs' job.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bus.model import BusParams, simulate_cycle  # noqa: E402
from models import camry, ev  # noqa: E402


@pytest.fixture(scope="module")
def trip_a01() -> pd.DataFrame:
    return pd.read_parquet(ROOT / "data" / "i3" / "TripA01.parquet")


def test_ev_signs_match_the_measurement(trip_a01: pd.DataFrame) -> None:
    sim = ev.simulate(trip_a01, version=1)
    traction = sim["T_mot"] > 20
    # Below -60 N·m the recovered power exceeds any base load the fit can give version 1.
    regen = sim["T_mot"] < -60
    # The logger counts discharge as negative current.
    assert (sim.loc[traction, "I_batt"] < 0).all()
    assert (sim.loc[regen, "I_batt"] > 0).mean() > 0.95
    assert sim["E_batt"].iloc[-1] > 0
    assert np.allclose(sim["P_batt"], -sim["U_batt"] * sim["I_batt"] / 1e3)


def test_ev_energy_on_fit_trip_within_five_percent(trip_a01: pd.DataFrame) -> None:
    voltage = trip_a01["Battery Voltage [V]"].to_numpy()
    current = trip_a01["Battery Current [A]"].to_numpy()
    measured = -np.trapezoid(voltage * current, trip_a01["Time [s]"].to_numpy()) / 3.6e6
    for version in (1, 2):
        simulated = ev.simulate(trip_a01, version=version)["E_batt"].iloc[-1]
        assert simulated == pytest.approx(measured, rel=0.05)


def test_ev_version_two_needs_elevation(trip_a01: pd.DataFrame) -> None:
    with pytest.raises(KeyError, match="Elevation"):
        ev.simulate(trip_a01[["Time [s]", "Velocity [km/h]"]], version=2)


def test_ev_auxiliary_load_adds_its_energy(trip_a01: pd.DataFrame) -> None:
    flat = trip_a01.assign(**{"Elevation [m]": 500.0})
    base = ev.simulate(flat.assign(**{"AirCon Power [kW]": 0.0}), version=2)
    loaded = ev.simulate(flat.assign(**{"AirCon Power [kW]": 1.0}), version=2)
    hours = trip_a01["Time [s]"].iloc[-1] / 3600
    extra = loaded["E_batt"].iloc[-1] - base["E_batt"].iloc[-1]
    # 1 kW more for the trip's duration, plus the resistive loss on the extra current.
    assert extra == pytest.approx(hours, rel=0.02)


def test_ev_grade_of_a_constant_slope() -> None:
    time = np.arange(0.0, 200.0, 0.1)
    speed = np.full_like(time, 10.0)
    elevation = 0.05 * speed * time
    theta = ev.road_grade(time, speed, elevation, 200.0)
    assert np.tan(theta[500:-500]) == pytest.approx(0.05, rel=1e-6)


def test_camry_cuts_fuel_on_decel_and_idles_at_rest() -> None:
    p = camry.load_params()
    time = np.arange(0.0, 30.0)
    speed = np.concatenate((np.zeros(10), np.linspace(0, 20, 10), np.linspace(20, 0, 10)))
    rate = camry.fuel_rate(time, speed, p)
    assert rate[:5] == pytest.approx(p.idle_flow_cc_s)
    assert rate[12:18].min() > p.idle_flow_cc_s
    assert (rate[21:28] == 0.0).all()


def test_bus_model_follows_its_cycle_and_keeps_soc_in_window() -> None:
    time = np.arange(0.0, 120.0, 0.01)
    cycle = np.interp(time, [0, 5, 25, 60, 80, 120], [0, 0, 40, 40, 0, 0])
    p = BusParams()
    out = simulate_cycle(time, cycle, p)
    assert np.abs(out["v"] - cycle).max() < 3.0
    assert out["SoC"].between(p.soc_min_pct - 0.5, p.soc_max_pct + 0.5).all()
    assert out["FCcum"].is_monotonic_increasing
    assert out["gear"].max() >= 3


def test_bus_accessory_load_adds_torque_and_fuel_only_while_fuelled() -> None:
    time = np.arange(0.0, 120.0, 0.01)
    cycle = np.interp(time, [0, 5, 25, 60, 80, 120], [0, 0, 40, 40, 0, 0])
    plain = simulate_cycle(time, cycle, BusParams())
    loaded = simulate_cycle(time, cycle, BusParams(accessory_torque_nm=25.0))
    # The accessory does not change how the bus drives; only the engine's load.
    assert np.array_equal(plain["v"], loaded["v"])
    extra = loaded["Teng"] - plain["Teng"]
    overrun = plain["FCinst"] == 0.0
    assert overrun.any()
    assert np.allclose(extra[~overrun], 25.0)
    assert np.allclose(extra[overrun], 0.0)
    assert (loaded["FCinst"][~overrun] > plain["FCinst"][~overrun]).all()
    assert (loaded["FCinst"][overrun] == 0.0).all()


def test_bus_answer_key_is_labelled_and_not_named_in_the_spec() -> None:
    key = json.loads((ROOT / "bus" / "data" / "undeclared_effects.json").read_text("utf-8"))
    assert key["label"].startswith("SYNTHETIC")
    spec = (ROOT / "specs" / "bus-mild-hybrid.hevval.yaml").read_text("utf-8").lower()
    assert "compressor" not in spec
    assert "p_air" not in spec
