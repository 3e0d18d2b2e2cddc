"""Generate the SYNTHETIC "measured" data of the mild-hybrid bus case.

The paper validates a forward-facing model of a post-transmission parallel mild-hybrid 18 t
double-deck bus against 100 Hz test data. That data is not public, so this script makes a
stand-in: a bus-like stop-and-go cycle, a richer "truth" simulation of the same bus driving it,
and a data logger that samples the truth the way a vehicle's CAN bus would.

The truth differs from ``bus/model.py`` in ways a real bus differs from its model: another
driver, turbocharger lag, torque interruptions during gear shifts, a load-dependent engine
efficiency, a little more mass, sensor noise, CAN rates and resolutions. It also carries one
physical effect that the model does not declare at all. What that is, is written to
``bus/data/undeclared_effects.json`` so that a diagnosis can be checked against it; the
validation spec does not name it.

    python bus/generate.py            # writes bus/data/bus_measured.parquet (+ the answer key)

Everything is seeded: running it again reproduces the same files.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

from bus.model import RPM, BusParams, engine_torque_limit  # noqa: E402

FloatArray = npt.NDArray[np.float64]

RATE_HZ = 100.0
SEED = 20180611
OUT = HERE / "data"


# --- the drive cycle ---------------------------------------------------------------------


def bus_cycle(seed: int = SEED, duration_s: float = 720.0) -> tuple[FloatArray, FloatArray]:
    """A stop-and-go route: stops 200-550 m apart, 12-35 s dwell, 25-48 km/h between stops."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE_HZ
    speeds: list[float] = [0.0] * int(8.0 * RATE_HZ)
    while len(speeds) * dt < duration_s - 60.0:
        cruise = rng.uniform(25.0, 48.0) / 3.6
        spacing = rng.uniform(200.0, 550.0)
        accel = rng.uniform(0.8, 1.2)
        decel = rng.uniform(0.9, 1.3)
        ramp_up = cruise**2 / (2 * accel)
        ramp_down = cruise**2 / (2 * decel)
        cruise_m = max(0.0, spacing - ramp_up - ramp_down)
        v = 0.0
        while v < cruise:
            v = min(cruise, v + accel * dt)
            speeds.append(v)
        if rng.random() < 0.4:
            # Traffic: slow down part-way, then pick up speed again.
            slow = cruise * rng.uniform(0.3, 0.7)
            speeds.extend([cruise] * int(0.3 * cruise_m / cruise * RATE_HZ))
            while v > slow:
                v = max(slow, v - decel * 0.6 * dt)
                speeds.append(v)
            speeds.extend([slow] * int(rng.uniform(2.0, 8.0) * RATE_HZ))
            while v < cruise:
                v = min(cruise, v + accel * 0.7 * dt)
                speeds.append(v)
            cruise_m *= 0.5
        speeds.extend([cruise] * int(cruise_m / cruise * RATE_HZ))
        while v > 0.0:
            v = max(0.0, v - decel * dt)
            speeds.append(v)
        speeds.extend([0.0] * int(rng.uniform(12.0, 35.0) * RATE_HZ))
    speeds.extend([0.0] * int(max(0.0, duration_s - len(speeds) * dt) * RATE_HZ))
    raw = np.asarray(speeds[: int(duration_s * RATE_HZ)])
    # A 1.5 s moving average limits the jerk, as a timetable-driven bus driver would.
    width = int(1.5 * RATE_HZ)
    smooth = np.convolve(np.pad(raw, width // 2, mode="edge"), np.ones(width) / width, "valid")
    smooth = np.maximum(smooth[: raw.size], 0.0)
    smooth[smooth < 0.05] = 0.0
    time = np.arange(raw.size) / RATE_HZ
    return time, smooth * 3.6


# --- the truth -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Truth:
    """How the real bus departs from the declared model."""

    extra_mass_kg: float = 400.0
    driver_kp_nm_per_m_s: float = 5000.0
    driver_ki_nm_per_m: float = 450.0
    driver_delay_s: float = 0.3
    turbo_time_constant_s: float = 0.4
    # Above this fraction of full-load torque the engine waits for boost.
    turbo_free_fraction: float = 0.5
    shift_time_s: float = 0.6
    efficiency_peak: float = 0.46
    efficiency_drop_at_no_load: float = 0.07
    # The undeclared effect: an engine-driven air compressor for brakes, doors and kneeling.
    compressor_torque_loaded_nm: float = 85.0
    compressor_torque_unloaded_nm: float = 5.0
    compressor_cut_in_bar: float = 7.0
    compressor_cut_out_bar: float = 8.2
    compressor_rate_bar_s_per_1000rpm: float = 0.035
    air_per_stop_bar: float = 0.40
    air_per_brake_kj: float = 0.0004


def simulate_truth(
    time_s: FloatArray, cycle_kmh: FloatArray, p: BusParams, t: Truth
) -> dict[str, FloatArray]:
    """The richer forward simulation; returns the true signals at 100 Hz."""
    n = time_s.size
    dt = 1.0 / RATE_HZ
    target = cycle_kmh / 3.6
    mass = p.mass_kg + t.extra_mass_kg
    m_eff = mass * (1.0 + p.rotating_mass_factor)
    f_roll = p.rolling_resistance * mass * 9.81
    k_aero = 0.5 * p.air_density_kg_m3 * p.cd_a_m2
    ratios = p.gear_ratios
    r, i_fd = p.wheel_radius_m, p.final_drive_ratio
    delay = round(t.driver_delay_s * RATE_HZ)
    capacity_as = p.battery_capacity_ah * 3600.0

    names = ("v", "Neng", "Teng", "FCinst", "SoC", "p_air", "compressor")
    out = {name: np.empty(n) for name in names}
    v = 0.0
    integral = 0.0
    gear = 1
    soc = p.initial_soc_pct
    engine_torque = 0.0
    shift_left = 0.0
    pressure = 8.0
    loading = False
    stop_clock = 0.0
    for k in range(n):
        seen = float(target[max(0, k - delay)])
        error = seen - v
        demand = t.driver_kp_nm_per_m_s * error + t.driver_ki_nm_per_m * integral
        omega_prop = v / r * i_fd
        rpm_in_gear = omega_prop * ratios[gear - 1] * RPM
        if shift_left <= 0.0:
            if rpm_in_gear > p.upshift_rpm and gear < len(ratios):
                gear += 1
                shift_left = t.shift_time_s
            elif rpm_in_gear < p.downshift_rpm and gear > 1:
                gear -= 1
                shift_left = t.shift_time_s
        ratio = ratios[gear - 1]
        rpm = max(p.idle_rpm, omega_prop * ratio * RPM)
        stopped = v <= 0.0 and seen <= 0.0

        # Air: each stop opens the doors and kneels once; braking uses air in proportion.
        if stopped:
            stop_clock += dt
            if stop_clock >= 2.0 and stop_clock - dt < 2.0:
                pressure -= t.air_per_stop_bar
        else:
            stop_clock = 0.0
        if pressure < t.compressor_cut_in_bar:
            loading = True
        elif pressure > t.compressor_cut_out_bar:
            loading = False
        if loading:
            pressure += t.compressor_rate_bar_s_per_1000rpm * rpm / 1000.0 * dt
            t_compressor = t.compressor_torque_loaded_nm
        else:
            t_compressor = t.compressor_torque_unloaded_nm

        t_motor = 0.0
        t_brake = 0.0
        wanted = 0.0
        if stopped:
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
            t_motor = min(demand - from_engine, motor_cap)
            wanted = from_engine / (ratio * p.gearbox_efficiency)
        else:
            regen_cap = p.motor_torque_max_nm
            if omega_prop > 1.0:
                regen_cap = min(regen_cap, p.motor_power_max_w / omega_prop)
            if soc >= p.soc_max_pct:
                regen_cap = 0.0
            t_motor = max(demand, -regen_cap)
            t_brake = min(-(demand - t_motor), p.brake_torque_max_nm)
            pressure -= t.air_per_brake_kj * t_brake * i_fd * v / r * dt / 1e3

        # Turbo lag: torque up to the boost-free fraction is immediate, the rest builds up.
        free = t.turbo_free_fraction * engine_torque_limit(rpm)
        if wanted <= free or wanted < engine_torque:
            engine_torque = wanted
        else:
            alpha = dt / (t.turbo_time_constant_s + dt)
            engine_torque = max(free, engine_torque + alpha * (wanted - engine_torque))
        if shift_left > 0.0:
            # The gearbox opens the driveline while it shifts.
            shift_left -= dt
            drive_torque = 0.0
        else:
            drive_torque = engine_torque

        prop = drive_torque * ratio * p.gearbox_efficiency + t_motor - t_brake
        f_wheel = prop * i_fd * p.final_drive_efficiency / r
        f_res = (f_roll if v > 0.0 else 0.0) + k_aero * v * v
        held = stopped or (v <= 0.0 and f_wheel <= f_res)
        accel = 0.0 if held else (f_wheel - f_res) / m_eff

        brake_torque = drive_torque + t_compressor
        omega = rpm / RPM
        load = min(1.0, max(0.0, brake_torque / engine_torque_limit(rpm)))
        efficiency = t.efficiency_peak - t.efficiency_drop_at_no_load * (1.0 - load) ** 2
        friction = omega * (p.friction_torque_nm + p.friction_torque_per_rad_s * omega)
        fuel = (brake_torque * omega + friction) / efficiency / p.fuel_lhv_j_per_g
        if demand < 0.0 and rpm > p.idle_rpm + 50.0:
            fuel = 0.0
            brake_torque = 0.0

        electric = t_motor * omega_prop
        electric = electric / p.motor_efficiency if electric > 0 else electric * p.motor_efficiency

        out["v"][k] = v * 3.6
        out["Neng"][k] = rpm
        out["Teng"][k] = brake_torque
        out["FCinst"][k] = fuel
        out["SoC"][k] = soc
        out["p_air"][k] = pressure
        out["compressor"][k] = 1.0 if loading else 0.0

        soc -= 100.0 * electric / p.battery_voltage_v * dt / capacity_as
        v = max(0.0, v + accel * dt)
        integral += error * dt
    return out


# --- the data logger -----------------------------------------------------------------------


def can_channel(
    x: FloatArray,
    *,
    rate_hz: float,
    resolution: float,
    noise: float,
    latency_frames: int,
    rng: np.random.Generator,
    average: bool = False,
) -> FloatArray:
    """Sample at a CAN rate (frame mean if ``average``), quantise, delay, hold at 100 Hz."""
    step = round(RATE_HZ / rate_hz)
    frames = x.size // step + 1
    padded = np.pad(x, (0, frames * step - x.size), mode="edge")
    sampled = padded.reshape(frames, step).mean(axis=1) if average else padded[::step]
    sampled = sampled + rng.normal(0.0, noise, sampled.size)
    sampled = np.round(sampled / resolution) * resolution
    held = np.repeat(sampled, step)[: x.size]
    shift = latency_frames * step
    return np.concatenate((np.full(shift, held[0]), held[: x.size - shift]))


def main() -> None:
    rng = np.random.default_rng(SEED + 1)
    time_s, cycle_kmh = bus_cycle()
    p = BusParams()
    truth = Truth()
    true = simulate_truth(time_s, cycle_kmh, p, truth)

    # J1939-like resolutions: engine speed 0.125 rpm, torque 1 % of a 1400 N·m reference,
    # fuel rate 0.05 L/h (0.0116 g/s at 0.835 kg/L), wheel-based speed 1/256 km/h.
    measured = pd.DataFrame(
        {
            "time": time_s,
            "v_cycle": np.round(cycle_kmh, 3),
            "v": np.maximum(
                can_channel(
                    true["v"], rate_hz=50, resolution=1 / 256, noise=0.05, latency_frames=1, rng=rng
                ),
                0.0,
            ),
            "Neng": can_channel(
                true["Neng"], rate_hz=20, resolution=0.125, noise=3.0, latency_frames=1, rng=rng
            ),
            "Teng": np.maximum(
                can_channel(
                    true["Teng"], rate_hz=10, resolution=14.0, noise=4.0, latency_frames=1, rng=rng
                ),
                0.0,
            ),
            "FCinst": np.maximum(
                can_channel(
                    true["FCinst"],
                    rate_hz=10,
                    resolution=0.05 * 0.835 / 3.6,
                    noise=0.01,
                    latency_frames=1,
                    rng=rng,
                    average=True,
                ),
                0.0,
            ),
            "p_air": can_channel(
                true["p_air"], rate_hz=1, resolution=0.01, noise=0.01, latency_frames=0, rng=rng
            ),
        }
    )
    OUT.mkdir(exist_ok=True)
    target = OUT / "bus_measured.parquet"
    measured.to_parquet(target, engine="pyarrow", compression="zstd", index=False)

    fuel_with = float(np.sum(true["FCinst"]) / RATE_HZ)
    duty = float(np.mean(true["compressor"]))
    key = {
        "label": "SYNTHETIC DATA - answer key for the bus case. Not used by the validation.",
        "undeclared_effect": {
            "name": "engine-driven air compressor",
            "what": (
                "An air compressor on the engine's accessory drive refills the brake, door and "
                "suspension air tank. It loads the engine with "
                f"{truth.compressor_torque_loaded_nm:g} N·m while pumping (tank below "
                f"{truth.compressor_cut_in_bar:g} bar until it reaches "
                f"{truth.compressor_cut_out_bar:g} bar) and {truth.compressor_torque_unloaded_nm:g}"
                " N·m otherwise. Each stop uses air for the doors and kneeling; braking uses "
                "air in proportion to the braking energy."
            ),
            "signals_affected": ["Teng", "FCinst", "FCcum"],
            "compressor_duty": round(duty, 3),
            "logged_channel": "p_air (tank pressure, bar, 1 Hz)",
        },
        "other_differences": {
            "extra_mass_kg": truth.extra_mass_kg,
            "driver": "PI gains differ; 0.3 s reaction delay",
            "turbo_lag": f"torque above {truth.turbo_free_fraction:.0%} of full load "
            f"builds with a {truth.turbo_time_constant_s} s time constant",
            "gear_shifts": f"{truth.shift_time_s} s torque interruption",
            "engine_efficiency": "falls at part load instead of the model's constant value",
            "logging": "CAN rates v 50 Hz, Neng 20 Hz, Teng/FCinst 10 Hz, p_air 1 Hz; "
            "one-frame latency; held (zero-order) to 100 Hz; J1939-like resolution and noise",
        },
        "truth_totals": {
            "fuel_g": round(fuel_with, 1),
            "duration_s": float(time_s[-1]),
        },
        "seed": SEED,
    }
    (OUT / "undeclared_effects.json").write_text(
        json.dumps(key, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    print(
        f"wrote {target.relative_to(HERE.parent)} ({target.stat().st_size} B, {len(measured)} rows)"
    )
    print(f"truth fuel {fuel_with:.1f} g over {time_s[-1]:.0f} s; compressor duty {duty:.0%}")


if __name__ == "__main__":
    main()
