"""Sprague–Geers and Russell: magnitude and phase errors, and their combination.

With m the measurement (reference), c the computation (model) and sums over the common grid
(the time step cancels):

* **Sprague–Geers** (Sprague & Geers 2004, *Int. J. Numer. Meth. Engng* 60; Schwer 2007,
  *Engineering with Computers* 23, eq. 1–3): ψ_mm = Σm², ψ_cc = Σc², ψ_mc = Σmc;
  M = √(ψ_cc/ψ_mm) − 1, P = arccos(ψ_mc/√(ψ_mm ψ_cc))/π, C = √(M² + P²).
  The magnitude keeps its square root: c = k·m gives M = k − 1 exactly, and P = 0
  (Sprague & Geers: the magnitude error is insensitive to phase, the phase error to magnitude).
* **Russell** (Russell 1997, *Shock and Vibration Symposium*; Schwer 2007 eq. 4–7):
  m_r = (ψ_cc − ψ_mm)/√(ψ_cc ψ_mm), RM = sign(m_r)·log₁₀(1 + |m_r|), RP = P (the same angle),
  RC = √(π/4 · (RM² + RP²)).

Neither defines a [0, 1] rating, so hevval scores 1 − C and 1 − RC, clipped to [0, 1]; C = 1
(score 0) is a 100 % magnitude error or a phase opposition. Both are invariant under a change of
units, not under an offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..registry import CharacteristicValue
from ._inputs import FloatArray, checked_pair, degenerate
from ._moments import Moments

__all__ = [
    "MagnitudePhase",
    "russell",
    "russell_characteristic",
    "russell_characteristic_from_moments",
    "sprague_geers",
    "sprague_geers_characteristic",
    "sprague_geers_characteristic_from_moments",
]


@dataclass(frozen=True)
class MagnitudePhase:
    magnitude: float
    phase: float
    combined: float


def _energy_ratio_and_phase(
    reference: FloatArray, simulated: FloatArray, metric: str
) -> tuple[float, float]:
    """√(ψ_cc/ψ_mm) and P; each signal scaled by its own peak, so no square under- or overflows."""
    ref, sim = checked_pair(reference, simulated, metric=metric)
    ref_peak = float(np.max(np.abs(ref)))
    sim_peak = float(np.max(np.abs(sim)))
    if sim_peak == 0.0:
        raise degenerate(
            metric,
            "the simulated signal is zero everywhere, so the phase error is undefined",
            "check the model output's column and scale",
        )
    m, c = ref / ref_peak, sim / sim_peak
    return _ratio_and_phase(float(m @ m), float(c @ c), float(m @ c), sim_peak / ref_peak, metric)


def _ratio_and_phase(
    mm: float, cc: float, mc: float, peak_ratio: float, metric: str
) -> tuple[float, float]:
    """√(ψ_cc/ψ_mm) and P from the sums of signals scaled by peaks whose ratio (sim over ref) is
    ``peak_ratio``."""
    ratio = peak_ratio * math.sqrt(cc / mm)
    if not (math.isfinite(ratio) and ratio > 0.0 and math.isfinite(1.0 / ratio)):
        raise degenerate(
            metric,
            f"the signals' magnitudes differ by a factor beyond the float range ({ratio:.3g})",
            "check the model output's column and scale",
        )
    cosine = max(-1.0, min(1.0, mc / math.sqrt(mm * cc)))
    return ratio, math.acos(cosine) / math.pi


# Sums of squares below this may have lost digits to underflow: the arrays decide instead.
_NORMAL_POWER = 2.0**-900


def _from_pass(m: Moments, metric: str) -> tuple[float, float] | None:
    """√(ψ_cc/ψ_mm) and P from the λ pass's sums, or None when the arrays must decide (a
    simulated signal that is zero, or sums near the ends of the float range)."""
    sums = m.check(metric).sums
    powers = (sums.ref_sq, sums.sim_sq)
    if not all(math.isfinite(p) and p >= _NORMAL_POWER for p in powers):
        return None
    return _ratio_and_phase(sums.ref_sq, sums.sim_sq, sums.cross, 1.0, metric)


def _sprague_geers(ratio: float, phase: float) -> MagnitudePhase:
    magnitude = ratio - 1.0
    return MagnitudePhase(magnitude, phase, math.hypot(magnitude, phase))


def _russell(ratio: float, phase: float) -> MagnitudePhase:
    # (ψ_cc − ψ_mm)/√(ψ_cc ψ_mm) = q − 1/q with q = √(ψ_cc/ψ_mm).
    relative = ratio - 1.0 / ratio
    magnitude = math.copysign(math.log10(1.0 + abs(relative)), relative)
    return MagnitudePhase(magnitude, phase, math.sqrt(math.pi / 4.0 * (magnitude**2 + phase**2)))


def sprague_geers(reference: FloatArray, simulated: FloatArray) -> MagnitudePhase:
    return _sprague_geers(*_energy_ratio_and_phase(reference, simulated, "sprague_geers"))


def russell(reference: FloatArray, simulated: FloatArray) -> MagnitudePhase:
    return _russell(*_energy_ratio_and_phase(reference, simulated, "russell"))


def _scored(e: MagnitudePhase, prefix: str) -> CharacteristicValue:
    """1 − combined error, clipped to [0, 1], with the three errors as components."""
    parts = {f"{prefix}M": e.magnitude, f"{prefix}P": e.phase, f"{prefix}C": e.combined}
    return CharacteristicValue(min(1.0, max(0.0, 1.0 - e.combined)), parts)


def sprague_geers_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``sprague_geers``: 1 − C, with M, P and C as components."""
    return _scored(sprague_geers(reference, simulated), "")


def russell_characteristic(
    reference: FloatArray, simulated: FloatArray, dt: float
) -> CharacteristicValue:
    """The registry's ``russell``: 1 − RC, with RM, RP and RC as components."""
    return _scored(russell(reference, simulated), "R")


def sprague_geers_characteristic_from_moments(m: Moments) -> CharacteristicValue | None:
    """:func:`sprague_geers_characteristic` from the λ pass's sums; None: take the arrays."""
    found = _from_pass(m, "sprague_geers")
    return None if found is None else _scored(_sprague_geers(*found), "")


def russell_characteristic_from_moments(m: Moments) -> CharacteristicValue | None:
    """:func:`russell_characteristic` from the λ pass's sums; None: take the arrays."""
    found = _from_pass(m, "russell")
    return None if found is None else _scored(_russell(*found), "R")
