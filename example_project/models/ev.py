"""Longitudinal energy model of a BMW i3 (60 Ah), driven by a measured speed trace.

A driver (feed-forward of the measured acceleration plus a proportional speed correction)
asks for a wheel force; the motor delivers it within its torque and power envelope through a
fixed gear, friction brakes supply what regeneration cannot, and the resulting electrical
power is drawn from a battery modelled as an open-circuit voltage behind a resistance.

Two versions share the code and differ only in what they declare:

* ``version=1`` drives on a flat road and knows no auxiliary consumer except a constant base
  load. It is the model as first written, and the example validates it to find out what it
  misses.
* ``version=2`` adds the road grade (from the smoothed ``Elevation [m]`` channel) and the
  measured heater and air-conditioning power as an electrical load.

``heater_aircon_gain`` (0 unless set) adds that many kW of battery power per kW of logged
heater and air-conditioning power, in either version: the fix ``hevval diagnose`` prints for
v1 ("add 1.15 × heating_aircon_kw and lower the model's constant by 1.75 kW") is
``params: {version: 1, heater_aircon_gain: 1.15, base_load_w: <fitted − 1750>}`` with both
channels under ``model.inputs``.

Sign convention (as in the measurement): ``I_batt`` is negative when the battery discharges.
``P_batt`` and ``E_batt`` count discharge as positive, in kW and kWh.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

__all__ = ["PARAMS_FILE", "EVParams", "load_params", "simulate", "simulate_arrays"]

FloatArray = npt.NDArray[np.float64]

PARAMS_FILE = Path(__file__).with_name("ev_params.json")

TIME = "Time [s]"
SPEED = "Velocity [km/h]"
ELEVATION = "Elevation [m]"
SOC = "SoC [%]"
HEATING = "Heating Power CAN [kW]"
AIRCON = "AirCon Power [kW]"

GRAVITY = 9.81


@dataclass(frozen=True)
class EVParams:
    """Model parameters. The defaults of the fitted ones are only starting guesses."""

    # Published vehicle data (BMW i3 60 Ah, 155/70 R19 tyres); not fitted.
    cd_a_m2: float = 0.29 * 2.38
    air_density_kg_m3: float = 1.2
    wheel_radius_m: float = 0.35
    gear_ratio: float = 9.665
    gear_efficiency: float = 0.97
    rotating_mass_factor: float = 0.05
    motor_torque_max_nm: float = 250.0
    motor_power_max_w: float = 125e3
    # The regeneration limits are the plateau of ``Motor Torque [Nm]`` and of motor power
    # seen on braking in the logged trips (about -87 N·m, about -58 kW).
    regen_torque_max_nm: float = 87.0
    regen_power_max_w: float = 58e3
    # Speed correction of the driver after the motor saturates, 1/s.
    driver_gain_per_s: float = 2.0
    # Road grade is taken over this distance: GPS elevation is coarse in steps of a metre.
    grade_window_m: float = 200.0
    # Payload beyond the fitted test mass.
    extra_mass_kg: float = 0.0
    # Fitted by ``fit_ev.py``.
    mass_kg: float = 1400.0
    rolling_resistance: float = 0.009
    copper_loss_w_per_nm2: float = 0.05
    power_loss_fraction: float = 0.05
    base_load_w: float = 500.0
    # kW of battery power per kW of logged heater + air-con power, on top of what the version
    # draws (v2 draws it once already); not fitted.
    heater_aircon_gain: float = 0.0
    ocv_at_0_soc_v: float = 330.0
    ocv_per_soc_v: float = 0.7
    internal_resistance_ohm: float = 0.1
    capacity_ah: float = 60.0
    initial_soc_pct: float = 80.0


FITTED = (
    "mass_kg",
    "rolling_resistance",
    "copper_loss_w_per_nm2",
    "power_loss_fraction",
    "base_load_w",
    "ocv_at_0_soc_v",
    "ocv_per_soc_v",
    "internal_resistance_ohm",
    "capacity_ah",
)


def load_params(version: int, path: Path | None = None) -> EVParams:
    """The fitted parameters of ``version`` from ``ev_params.json``, or the defaults."""
    source = PARAMS_FILE if path is None else path
    if not source.exists():
        return EVParams()
    stored = json.loads(source.read_text(encoding="utf-8"))
    values = stored.get("versions", {}).get(str(version), {}).get("params", {})
    unknown = set(values) - {f.name for f in fields(EVParams)}
    if unknown:
        raise ValueError(
            f"{source.name} sets unknown parameter(s) {sorted(unknown)}; "
            "delete it and rerun fit_ev.py"
        )
    return replace(EVParams(), **{k: float(v) for k, v in values.items()})


def _moving_average(x: FloatArray, width: int) -> FloatArray:
    if width <= 1:
        return x
    kernel = np.ones(width) / width
    padded = np.pad(x, (width // 2, width - 1 - width // 2), mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def road_grade(
    time_s: FloatArray, speed_m_s: FloatArray, elevation_m: FloatArray, window_m: float
) -> FloatArray:
    """Slope angle (rad) from elevation against travelled distance.

    Differentiating over distance rather than time keeps the grade finite at standstill,
    where the GPS altitude still wanders.
    """
    distance = np.concatenate(
        ([0.0], np.cumsum(0.5 * (speed_m_s[1:] + speed_m_s[:-1]) * np.diff(time_s)))
    )
    step = 5.0
    if distance[-1] < 2 * step:
        return np.zeros_like(time_s)
    grid = np.arange(0.0, distance[-1] + step, step)
    keep = np.concatenate(([True], np.diff(distance) > 0))
    height = np.interp(grid, distance[keep], elevation_m[keep])
    smooth = _moving_average(height, max(1, round(window_m / step)))
    slope = np.gradient(smooth, step)
    return np.arctan(np.interp(distance, grid, slope))


@dataclass(frozen=True)
class Trace:
    """Simulated signals on the input time base."""

    time: FloatArray
    speed_kmh: FloatArray
    motor_torque_nm: FloatArray
    battery_power_kw: FloatArray
    battery_current_a: FloatArray
    battery_voltage_v: FloatArray
    battery_energy_kwh: FloatArray
    soc_pct: FloatArray


def simulate_arrays(
    time_s: FloatArray,
    speed_kmh: FloatArray,
    p: EVParams,
    *,
    grade_rad: FloatArray | None = None,
    auxiliary_w: FloatArray | None = None,
) -> Trace:
    """Run the model on plain arrays; ``simulate`` is the pandas front end."""
    n = time_s.size
    v_ref = speed_kmh / 3.6
    dt = np.diff(time_s)
    # Forward difference: when the motor is not saturated the model follows the trace exactly.
    a_ff = np.append(np.diff(v_ref) / dt, 0.0)
    theta = np.zeros(n) if grade_rad is None else grade_rad
    mass = p.mass_kg + p.extra_mass_kg
    m_eff = mass * (1.0 + p.rotating_mass_factor)
    r, g_ratio, eta = p.wheel_radius_m, p.gear_ratio, p.gear_efficiency
    f_roll_full = p.rolling_resistance * mass * GRAVITY * np.cos(theta)
    f_grade = mass * GRAVITY * np.sin(theta)
    k_aero = 0.5 * p.air_density_kg_m3 * p.cd_a_m2

    speed = np.empty(n)
    torque = np.zeros(n)
    v = float(v_ref[0])
    # Scalar loop: the speed at each step depends on whether the motor saturated before.
    for k in range(n):
        speed[k] = v
        if k == n - 1:
            break
        # Rolling resistance fades in over the first 0.3 m/s so a stopped car needs no torque.
        f_res = float(f_roll_full[k]) * min(1.0, v / 0.3) + k_aero * v * v + float(f_grade[k])
        a_dem = float(a_ff[k]) + p.driver_gain_per_s * (float(v_ref[k]) - v)
        f_dem = m_eff * a_dem + f_res
        if v <= 0.0 and f_dem <= 0.0:
            # Held by the brakes.
            v = 0.0
            continue
        omega = v / r * g_ratio
        t_dem = f_dem * r / g_ratio / eta if f_dem > 0 else f_dem * r / g_ratio * eta
        t_hi = p.motor_torque_max_nm
        t_lo = -p.regen_torque_max_nm
        if omega > 1.0:
            t_hi = min(t_hi, p.motor_power_max_w / omega)
            t_lo = max(t_lo, -p.regen_power_max_w / omega)
        t_mot = min(max(t_dem, t_lo), t_hi)
        torque[k] = t_mot
        # Friction brakes add whatever deceleration regeneration cannot deliver.
        f_wheel = f_dem if f_dem <= 0 else t_mot * g_ratio * eta / r
        v = max(0.0, v + (f_wheel - f_res) / m_eff * float(dt[k]))

    omega_m = speed / r * g_ratio
    mechanical = torque * omega_m
    # Losses grow with the power converted (switching, iron) and with torque squared (copper).
    losses = p.power_loss_fraction * np.abs(mechanical) + p.copper_loss_w_per_nm2 * torque**2
    electrical = mechanical + losses
    load = electrical + p.base_load_w
    if auxiliary_w is not None:
        load = load + auxiliary_w

    # The open-circuit voltage depends on SoC, which depends on the current drawn; SoC moves
    # slowly, so a few fixed-point passes over the whole trace converge.
    step = np.append(dt, 0.0)
    soc = np.full(n, p.initial_soc_pct)
    discharge = np.zeros(n)
    ocv = np.zeros(n)
    for _ in range(4):
        ocv = p.ocv_at_0_soc_v + p.ocv_per_soc_v * soc
        root = np.sqrt(np.maximum(ocv**2 - 4.0 * p.internal_resistance_ohm * load, 0.0))
        discharge = (ocv - root) / (2.0 * p.internal_resistance_ohm)
        charge_as = np.concatenate(([0.0], np.cumsum(discharge[:-1] * step[:-1])))
        soc = p.initial_soc_pct - 100.0 * charge_as / (3600.0 * p.capacity_ah)
    voltage = ocv - p.internal_resistance_ohm * discharge
    power_w = voltage * discharge
    energy_ws = np.concatenate(([0.0], np.cumsum(0.5 * (power_w[1:] + power_w[:-1]) * dt)))
    return Trace(
        time=time_s,
        speed_kmh=speed * 3.6,
        motor_torque_nm=torque,
        battery_power_kw=power_w / 1e3,
        battery_current_a=-discharge,
        battery_voltage_v=voltage,
        battery_energy_kwh=energy_ws / 3.6e6,
        soc_pct=soc,
    )


def _column(reference: pd.DataFrame, name: str, version: int) -> FloatArray:
    if name not in reference.columns:
        raise KeyError(
            f"models.ev version {version} needs the reference channel {name!r}; "
            f"add it to model.inputs in the spec (got {sorted(map(str, reference.columns))})"
        )
    return reference[name].to_numpy(dtype=np.float64)


def _heater_aircon_w(reference: pd.DataFrame, version: int, *, required: bool) -> FloatArray:
    """The logged heater and air-conditioning power in W, a gap counting as 0; a channel
    missing from ``reference`` counts as 0 too unless ``required``."""
    load = np.zeros(len(reference))
    for name in (HEATING, AIRCON):
        if required or name in reference.columns:
            load += 1e3 * np.nan_to_num(_column(reference, name, version))
    return load


def simulate(
    reference: pd.DataFrame,
    *,
    version: int = 1,
    params_file: str | None = None,
    auxiliary_w: FloatArray | None = None,
    **overrides: Any,
) -> pd.DataFrame:
    """Simulate one trip.

    ``reference`` needs ``Time [s]`` and ``Velocity [km/h]``; ``SoC [%]`` (first valid sample
    only, as the initial state) is used when present. Version 2 also needs ``Elevation [m]``;
    ``Heating Power CAN [kW]`` and ``AirCon Power [kW]`` are added as loads when present, and
    needed when ``heater_aircon_gain`` is set. ``overrides`` replace single parameters of the
    fitted set; ``auxiliary_w`` is one more electrical load in W on the reference's time base
    (a caller's own term: a load under test).
    """
    if version not in (1, 2):
        raise ValueError(f"version must be 1 or 2 (got {version!r})")
    known = {f.name for f in fields(EVParams)}
    unknown = set(overrides) - known
    if unknown:
        raise TypeError(f"unknown EV parameter(s) {sorted(unknown)}; known: {sorted(known)}")
    p = load_params(version, None if params_file is None else Path(params_file))
    if SOC in reference.columns:
        valid = reference[SOC].dropna()
        if not valid.empty:
            p = replace(p, initial_soc_pct=float(valid.iloc[0]))
    p = replace(p, **{k: float(v) for k, v in overrides.items()})

    time_s = _column(reference, TIME, version)
    speed_kmh = _column(reference, SPEED, version)
    grade = None
    auxiliary = None
    if version == 2:
        elevation = _column(reference, ELEVATION, version)
        grade = road_grade(time_s, speed_kmh / 3.6, elevation, p.grade_window_m)
        auxiliary = _heater_aircon_w(reference, version, required=False)
    if p.heater_aircon_gain != 0.0:
        extra = p.heater_aircon_gain * _heater_aircon_w(reference, version, required=True)
        auxiliary = extra if auxiliary is None else auxiliary + extra
    if auxiliary_w is not None:
        added = np.asarray(auxiliary_w, dtype=np.float64)
        auxiliary = added if auxiliary is None else auxiliary + added
    trace = simulate_arrays(time_s, speed_kmh, p, grade_rad=grade, auxiliary_w=auxiliary)
    frame: pd.DataFrame = pd.DataFrame(
        {
            "time": trace.time,
            "v": trace.speed_kmh,
            "T_mot": trace.motor_torque_nm,
            "P_batt": trace.battery_power_kw,
            "I_batt": trace.battery_current_a,
            "U_batt": trace.battery_voltage_v,
            "E_batt": trace.battery_energy_kwh,
            "SoC": trace.soc_pct,
        }
    )
    return frame
