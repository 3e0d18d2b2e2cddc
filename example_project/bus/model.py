"""Forward-facing model of a post-transmission parallel mild-hybrid double-deck bus (synthetic).

This is the model under test in the synthetic case that mirrors the paper's bus study. A PI
driver follows the drive cycle; a rule-based energy management splits the propshaft torque
between the diesel engine (behind a 6-speed automatic gearbox) and an electric machine on the
propshaft after the gearbox; the engine's fuel flow comes from a Willans-line fuel map.

Energy management rules:

* traction: the electric machine supplies the propshaft torque above a threshold (and whatever
  the engine cannot), while the state of charge is above its lower limit;
* braking: the machine regenerates up to its limit while the state of charge is below its
  upper limit; friction brakes supply the rest;
* the engine idles at stops and is fuelled off on overrun.

Input: the cycle speed (km/h) against time. Output columns: ``time`` (s), ``v`` (km/h),
``Neng`` (rpm), ``Teng`` (N·m), ``FCinst`` (g/s), ``FCcum`` (g), ``SoC`` (%), ``Tmot`` (N·m at
the propshaft) and ``gear``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

__all__ = [
    "BusParams",
    "engine_torque_limit",
    "fuel_rate_g_s",
    "simulate",
    "simulate_cycle",
]

FloatArray = npt.NDArray[np.float64]

GRAVITY = 9.81
RPM = 30.0 / math.pi  # rad/s → rpm


@dataclass(frozen=True)
class BusParams:
    """Parameters of the declared model (a part-laden 18 t double-deck bus)."""

    mass_kg: float = 15000.0
    rotating_mass_factor: float = 0.06
    rolling_resistance: float = 0.008
    cd_a_m2: float = 6.0
    air_density_kg_m3: float = 1.2
    wheel_radius_m: float = 0.5
    final_drive_ratio: float = 5.4
    final_drive_efficiency: float = 0.96
    gear_ratios: tuple[float, ...] = (3.36, 1.91, 1.42, 1.0, 0.72, 0.62)
    gearbox_efficiency: float = 0.95
    upshift_rpm: float = 1500.0
    downshift_rpm: float = 750.0
    idle_rpm: float = 600.0
    # Willans line: fuel power = (brake power + friction power) / indicated efficiency.
    friction_torque_nm: float = 100.0
    friction_torque_per_rad_s: float = 0.1
    indicated_efficiency: float = 0.45
    fuel_lhv_j_per_g: float = 42800.0
    # Electric machine on the propshaft.
    motor_torque_max_nm: float = 900.0
    motor_power_max_w: float = 60e3
    motor_efficiency: float = 0.9
    assist_threshold_nm: float = 1500.0
    battery_voltage_v: float = 600.0
    battery_capacity_ah: float = 8.0
    soc_min_pct: float = 40.0
    soc_max_pct: float = 70.0
    initial_soc_pct: float = 55.0
    # PI driver acting on the speed error (m/s) and giving a propshaft torque demand.
    driver_kp_nm_per_m_s: float = 6000.0
    driver_ki_nm_per_m: float = 600.0
    brake_torque_max_nm: float = 12000.0
    # Engine-driven accessories (air compressor, alternator, fan), as a mean torque at the
    # crankshaft. Version 1 has none; see the bus case in docs/closing-the-loop.md.
    accessory_torque_nm: float = 0.0


def engine_torque_limit(rpm: float) -> float:
    """Full-load torque (N·m) of the 7.7 L diesel at ``rpm``."""
    if rpm <= 600.0:
        return 700.0
    if rpm <= 1100.0:
        return 700.0 + (rpm - 600.0) * 1.0
    if rpm <= 1700.0:
        return 1200.0
    return max(0.0, 1200.0 - (rpm - 1700.0) * 0.6)


def fuel_rate_g_s(rpm: float, torque_nm: float, p: BusParams, *, overrun: bool = False) -> float:
    """Willans-line fuel flow; zero on overrun (braking demand above idle speed)."""
    omega = rpm / RPM
    if overrun and rpm > p.idle_rpm + 50.0:
        return 0.0
    friction = omega * (p.friction_torque_nm + p.friction_torque_per_rad_s * omega)
    brake = max(torque_nm, 0.0) * omega
    return (brake + friction) / p.indicated_efficiency / p.fuel_lhv_j_per_g


def simulate_cycle(time_s: FloatArray, cycle_kmh: FloatArray, p: BusParams) -> pd.DataFrame:
    """Run the forward model along a cycle; the step is the cycle's sample spacing."""
    n = time_s.size
    target = cycle_kmh / 3.6
    dt = np.append(np.diff(time_s), 0.0)
    m_eff = p.mass_kg * (1.0 + p.rotating_mass_factor)
    f_roll = p.rolling_resistance * p.mass_kg * GRAVITY
    k_aero = 0.5 * p.air_density_kg_m3 * p.cd_a_m2
    ratios = p.gear_ratios
    r, i_fd = p.wheel_radius_m, p.final_drive_ratio
    capacity_as = p.battery_capacity_ah * 3600.0

    out_v = np.empty(n)
    out_n = np.empty(n)
    out_t = np.empty(n)
    out_fc = np.empty(n)
    out_soc = np.empty(n)
    out_mot = np.empty(n)
    out_gear = np.empty(n)

    v = float(target[0])
    integral = 0.0
    gear = 1
    soc = p.initial_soc_pct
    for k in range(n):
        step = float(dt[k])
        error = float(target[k]) - v
        demand = p.driver_kp_nm_per_m_s * error + p.driver_ki_nm_per_m * integral
        omega_prop = v / r * i_fd

        # Shift on engine speed with hysteresis, one gear at a time.
        rpm_in_gear = omega_prop * ratios[gear - 1] * RPM
        if rpm_in_gear > p.upshift_rpm and gear < len(ratios):
            gear += 1
        elif rpm_in_gear < p.downshift_rpm and gear > 1:
            gear -= 1
        ratio = ratios[gear - 1]
        rpm = max(p.idle_rpm, omega_prop * ratio * RPM)

        t_engine = 0.0
        t_motor = 0.0
        t_brake = 0.0
        stopped = v <= 0.0 and float(target[k]) <= 0.0
        if stopped:
            demand = 0.0
            integral = 0.0
        elif demand >= 0.0:
            motor_cap = p.motor_torque_max_nm
            if omega_prop > 1.0:
                motor_cap = min(motor_cap, p.motor_power_max_w / omega_prop)
            if soc <= p.soc_min_pct:
                motor_cap = 0.0
            t_motor = min(max(demand - p.assist_threshold_nm, 0.0), motor_cap)
            engine_cap = engine_torque_limit(rpm) * ratio * p.gearbox_efficiency
            from_engine = min(demand - t_motor, engine_cap)
            # The machine also covers what the engine cannot deliver.
            t_motor = min(demand - from_engine, motor_cap)
            t_engine = from_engine / (ratio * p.gearbox_efficiency)
        else:
            regen_cap = p.motor_torque_max_nm
            if omega_prop > 1.0:
                regen_cap = min(regen_cap, p.motor_power_max_w / omega_prop)
            if soc >= p.soc_max_pct:
                regen_cap = 0.0
            t_motor = max(demand, -regen_cap)
            t_brake = min(-(demand - t_motor), p.brake_torque_max_nm)

        prop = t_engine * ratio * p.gearbox_efficiency + t_motor - t_brake
        f_wheel = prop * i_fd * p.final_drive_efficiency / r
        f_res = (f_roll if v > 0.0 else 0.0) + k_aero * v * v
        held = stopped or (v <= 0.0 and f_wheel <= f_res)
        accel = 0.0 if held else (f_wheel - f_res) / m_eff

        electric = t_motor * omega_prop
        electric = electric / p.motor_efficiency if electric > 0 else electric * p.motor_efficiency

        out_v[k] = v
        out_n[k] = rpm
        overrun = demand < 0.0 and rpm > p.idle_rpm + 50.0
        # On overrun the wheels turn the engine and drive the accessories; it burns no fuel
        # and its reported torque is zero.
        brake = 0.0 if overrun else t_engine + p.accessory_torque_nm
        out_t[k] = brake
        out_fc[k] = fuel_rate_g_s(rpm, brake, p, overrun=overrun)
        out_soc[k] = soc
        out_mot[k] = t_motor
        out_gear[k] = gear

        soc -= 100.0 * electric / p.battery_voltage_v * step / capacity_as
        v = max(0.0, v + accel * step)
        integral += error * step

    fc_cum = np.concatenate(([0.0], np.cumsum(0.5 * (out_fc[1:] + out_fc[:-1]) * dt[:-1])))
    frame: pd.DataFrame = pd.DataFrame(
        {
            "time": time_s,
            "v": out_v * 3.6,
            "Neng": out_n,
            "Teng": out_t,
            "FCinst": out_fc,
            "FCcum": fc_cum,
            "SoC": out_soc,
            "Tmot": out_mot,
            "gear": out_gear,
        }
    )
    return frame


def simulate(
    reference: pd.DataFrame, *, cycle: str = "v_cycle", time: str = "time", **overrides: Any
) -> pd.DataFrame:
    """Callable for pytest-hevval: drive the cycle held in the reference's ``cycle`` column."""
    known = {f.name for f in fields(BusParams)}
    unknown = set(overrides) - known
    if unknown:
        raise TypeError(f"unknown bus parameter(s) {sorted(unknown)}; known: {sorted(known)}")
    for name in (time, cycle):
        if name not in reference.columns:
            raise KeyError(f"bus.model needs the column {name!r} (got {list(reference.columns)})")
    p = replace(BusParams(), **overrides)
    return simulate_cycle(
        reference[time].to_numpy(dtype=np.float64),
        reference[cycle].to_numpy(dtype=np.float64),
        p,
    )
