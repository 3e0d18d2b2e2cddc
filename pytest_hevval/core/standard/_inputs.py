"""The input rules every standard metric shares: those of λ1–λ6, checked once."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ...errors import DegenerateSignalError

FloatArray = npt.NDArray[np.float64]


def checked_pair(
    reference: npt.ArrayLike, simulated: npt.ArrayLike, *, metric: str, min_samples: int = 3
) -> tuple[FloatArray, FloatArray]:
    """Both signals as float64, or DegenerateSignalError for the inputs λ1–λ6 refuse too.

    Refused: shapes other than two equal one-dimensional arrays, fewer than ``min_samples``
    samples, NaN or inf, and a constant reference (every standard metric normalises by the
    reference's spread, magnitude or slope).
    """
    ref = np.asarray(reference)
    sim = np.asarray(simulated)
    if ref.ndim != 1 or sim.ndim != 1 or ref.shape != sim.shape:
        raise DegenerateSignalError(
            f"{metric}: signals must be one-dimensional and of equal length "
            f"(got shapes {ref.shape} and {sim.shape})",
            hint="align both onto one time grid first",
        )
    if ref.shape[0] < min_samples:
        raise DegenerateSignalError(
            f"{metric}: at least {min_samples} samples are needed (got {ref.shape[0]})",
            hint="widen the window or raise the sample rate",
        )
    ref = ref.astype(np.float64, copy=False)
    sim = sim.astype(np.float64, copy=False)
    for name, arr in (("reference", ref), ("simulated", sim)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise DegenerateSignalError(
                f"{metric}: {name} signal contains NaN or inf (first at sample {int(bad[0])})",
                hint="set a gap policy (nan: omit) or clean the data",
            )
    if float(np.ptp(ref)) == 0.0:
        raise constant_reference(metric)
    return ref, sim


def constant_reference(metric: str) -> DegenerateSignalError:
    """The error for a constant reference: every standard metric normalises by its spread,
    magnitude or slope."""
    return DegenerateSignalError(
        f"{metric}: the reference is constant, so the metric is undefined",
        hint="compare a signal that varies, or leave this metric off for it",
    )


def power_of_two_exponent(peak: float) -> int:
    """The k that brings ``peak`` into [0.5, 1) as peak·2^k; 0 for a zero or non-finite peak.

    Multiplying by 2^k only changes the exponent, so values scaled by it (``np.ldexp``) keep
    every bit and every ratio between them, as long as none leaves the normal float range: a
    metric computed on them gives the same bits for data in any unit that differs by a power
    of two, and values of about 1 have squares and sums far from overflow and underflow.
    """
    if peak == 0.0 or not math.isfinite(peak):
        return 0
    return -math.frexp(peak)[1]


def degenerate(metric: str, problem: str, hint: str) -> DegenerateSignalError:
    """The error for an input on which ``metric``'s formula divides by zero."""
    return DegenerateSignalError(f"{metric}: {problem}", hint=hint)
