"""The inputs of a diagnosis checked and brought to scale: the two signals and the candidates as
finite float64 series of one length, the settings in range, and power-of-two rescaling that
keeps sums of squares of very large or very small signals inside float64 without changing a
single fraction or p-value."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import DegenerateSignalError, SpecError
from ..importance import MAX_TERMS
from ..stats import FloatArray
from .findings import Candidate
from .thresholds import _KINDS


def _as_signal(values: npt.ArrayLike, what: str) -> FloatArray:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DegenerateSignalError(f"{what} is not numeric: {exc}") from exc
    if array.ndim != 1:
        raise DegenerateSignalError(f"{what} must be one-dimensional, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise DegenerateSignalError(
            f"{what} contains {bad} NaN or infinite value(s)",
            hint="fill or drop the gaps before diagnosing the residual",
        )
    return array


def _checked_dt(dt: Any) -> float:
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating, np.integer)):
        raise DegenerateSignalError(f"dt must be a number of seconds, got {dt!r}")
    if not math.isfinite(float(dt)) or float(dt) <= 0.0:
        raise DegenerateSignalError(f"dt must be a positive, finite number of seconds, got {dt}")
    return float(dt)


def _check_settings(alpha: float, max_selected: int, max_samples: int) -> None:
    if not 0.0 < alpha < 1.0:
        raise SpecError(f"alpha must lie strictly between 0 and 1, got {alpha}")
    if not 0 <= max_selected < MAX_TERMS:
        # The shares are exact over every subset of the effects and the intercept.
        raise SpecError(f"max_selected must lie between 0 and {MAX_TERMS - 1}, got {max_selected}")
    if max_samples < 10:
        raise SpecError(f"max_samples must be at least 10, got {max_samples}")


_UserSeries = list[tuple[str, str, FloatArray]]


def _checked_inputs(
    reference: npt.ArrayLike, simulated: npt.ArrayLike, candidates: Sequence[Candidate]
) -> tuple[FloatArray, FloatArray, _UserSeries, set[str]]:
    """The two signals and the user's candidates as finite float64 series of one length."""
    ref = _as_signal(reference, "reference")
    sim = _as_signal(simulated, "simulated")
    if ref.shape[0] != sim.shape[0]:
        raise DegenerateSignalError(
            f"reference has {ref.shape[0]} samples but simulated has {sim.shape[0]}",
            hint="align both signals on one time grid first",
        )
    n = ref.shape[0]
    if n < 10:
        raise DegenerateSignalError(f"at least 10 samples are needed, got {n}")
    names: set[str] = set()
    for cand in candidates:
        if cand.kind not in _KINDS:
            raise SpecError(
                f"candidate {cand.name!r} has kind {cand.kind!r}; "
                f"expected one of {', '.join(_KINDS)}"
            )
        if cand.name in names:
            raise SpecError(f"candidate name {cand.name!r} is used twice")
        names.add(cand.name)
    user = [
        (c.name, str(c.kind), _as_signal(c.values, f"candidate {c.name!r}")) for c in candidates
    ]
    for name, _, values in user:
        if values.shape[0] != n:
            raise DegenerateSignalError(
                f"candidate {name!r} has {values.shape[0]} samples, the signals have {n}",
                key=name,
            )
    return ref, sim, user, names


def _rescaled_candidates(user: _UserSeries, s_sig: float) -> tuple[_UserSeries, dict[str, float]]:
    """Each candidate scaled by its own power of two; ``units`` turns coefficients back."""
    units: dict[str, float] = {}
    scaled: _UserSeries = []
    for name, kind, values in user:
        c = _pow2_scale(np.max(np.abs(values), initial=0.0))
        units[name] = c / s_sig
        scaled.append((name, kind, values * c))
    return scaled, units


def _pow2_scale(magnitude: float) -> float:
    """The power of two that brings ``magnitude`` into [0.5, 1); 1 for zero."""
    if magnitude <= 0.0 or not math.isfinite(magnitude):
        return 1.0
    return math.ldexp(1.0, -math.frexp(magnitude)[1])


def _varies(x: FloatArray) -> bool:
    return float(np.ptp(x)) > 1e-12 * max(float(np.max(np.abs(x))), 1e-300)


def _free_name(name: str, taken: set[str]) -> str:
    return name if name not in taken else f"{name} (automatic)"
