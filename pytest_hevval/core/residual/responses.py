"""Channels set apart before the selection: those the spec declares as responses, echoes of the
measured signal (instruments, derivatives and integrals of it) and consequences of what the
model already reproduces. They are never offered as the missing effect."""

from __future__ import annotations

from collections.abc import Collection

import numpy as np

from ..lag import search_lag
from ..stats import FloatArray, block_means, dot
from .findings import Response
from .inference import _full_rate_r2
from .inputs import _UserSeries, _varies
from .thresholds import (
    ECHO_INCREMENT_MIN_R2,
    ECHO_MIN_R2,
    ECHO_SIMULATED_RATIO,
    ECHO_WHOLE_MIN_R2,
    ECHO_WHOLE_RATIO,
    MIN_SLOW_BLOCKS,
    RESPONSE_LEAD_WINDOW_S,
    RESPONSE_MIN_LEAD_S,
    RESPONSE_MIN_R2,
    RESPONSE_RESIDUAL_RATIO,
    SLOW_SCALE_S,
)


def _split_responses(
    ref: FloatArray,
    sim: FloatArray,
    dt: float,
    user: _UserSeries,
    declared_responses: Collection[str],
    declared_causes: Collection[str],
    exogenous: Collection[str] = (),
) -> tuple[_UserSeries, tuple[Response, ...]]:
    """The user's candidates that may be causes, and those set apart as responses.

    A channel x is set apart when the spec says so (``declared``), or when it is

    * an **echo** of the scored signal: on block means of :data:`SLOW_SCALE_S`, the measured
      signal explains at least :data:`ECHO_MIN_R2` of x's variance (an instrument of it, its
      derivative: the bus voltage, the state of charge's rate for a battery power) or
      :data:`ECHO_INCREMENT_MIN_R2` of the variance of x's increments (its integral: the
      state of charge), and the simulated signal at least :data:`ECHO_SIMULATED_RATIO` of
      that; or the measured signal explains at least :data:`ECHO_WHOLE_MIN_R2` of x and at
      least :data:`ECHO_WHOLE_RATIO` of what its simulated part and the residual explain
      with coefficients of their own, and the simulated signal at least
      :data:`RESPONSE_MIN_R2` (x responds to the measured signal as a whole; one that leads it
      acts on it and is ``reproduced``). Echoes are never causes, whatever moves them;
    * a **consequence** of what the model reproduces (``follows``), unless it is exogenous:
      on the same block means, (1) the simulated signal explains at least
      :data:`RESPONSE_MIN_R2` of its variance, (2) the residual adds less than
      :data:`RESPONSE_RESIDUAL_RATIO` + var(r) / var(sim) of that on top (what a response to
      the whole measured signal gets from r), and (3) x does not lead the measured signal by
      :data:`RESPONSE_MIN_LEAD_S` or more; a channel that meets (1) and (2) but leads (a
      pedal position) is a cause the model already reproduces through its inputs
      (``reproduced``), no effect it lacks.

    The consequence test asks the simulated signal, not the measured one: a missing load is
    part of the measured signal, so the measured signal always "explains" it, while a response
    to what the model reproduces moves with the simulation and a missing load moves with the
    residual only. No running sum enters either test: two slowly trending series correlate
    whatever their causes. The spec's causes are never set apart.
    """
    kept: _UserSeries = []
    echoes: list[Response] = []
    residual = ref - sim
    lead_window = max(1, round(RESPONSE_LEAD_WINDOW_S / dt))
    sim_varies = _varies(sim)
    slow = max(1, round(SLOW_SCALE_S / dt))
    if ref.shape[0] // slow < MIN_SLOW_BLOCKS:
        slow = 1
    ref_s, sim_s = block_means(ref, slow), block_means(sim, slow)
    r_s = ref_s - sim_s
    residual_ratio = float(np.var(r_s)) / max(float(np.var(sim_s)), 1e-300)
    for name, kind, values in user:
        if kind in ("lag", "gain") or name in declared_causes or not _varies(values):
            kept.append((name, kind, values))
            continue
        explains = _full_rate_r2(residual, [values])
        if name in declared_responses:
            echoes.append(Response(name, kind, "declared", 0.0, 0.0, 0.0, explains))
            continue
        x_s = block_means(values, slow)
        whole = _full_rate_r2(x_s, [ref_s])
        instrument = max(
            _echo_share(x_s, ref_s, sim_s),
            _echo_share(np.diff(x_s), ref_s[1:], sim_s[1:], ECHO_INCREMENT_MIN_R2),
        )
        # A response moves with the simulated part too; a missing load that makes most of
        # the measured signal's slow variation does not.
        parts = _full_rate_r2(x_s, [sim_s, r_s])
        responds = (
            whole >= ECHO_WHOLE_MIN_R2
            and whole >= ECHO_WHOLE_RATIO * parts
            and _full_rate_r2(x_s, [sim_s]) >= RESPONSE_MIN_R2
        )
        if instrument > 0.0 or responds:
            # One that leads the measured signal acts on it (a pedal): it is no echo, but
            # what it does the measured signal holds whole, and the model reproduces through
            # its inputs.
            # A derivative's lead is its smoothing window's, not the channel's.
            acts = instrument == 0.0 and kind != "derivative"
            lead = _lead(ref, values, lead_window) if acts else 0
            reason = "reproduced" if lead * dt >= RESPONSE_MIN_LEAD_S - 0.5 * dt else "echo"
            echoes.append(
                Response(name, kind, reason, max(instrument, whole), 0.0, lead * dt, explains)
            )
            continue
        if name in exogenous or not sim_varies:
            kept.append((name, kind, values))
            continue
        # On the slow scale, as the echo test: a quantised channel (a state of charge shown in
        # whole percent) or its rate is resolved only there.
        by_sim = _full_rate_r2(x_s, [sim_s])
        added = _full_rate_r2(x_s, [sim_s, r_s]) - by_sim
        allowed = RESPONSE_RESIDUAL_RATIO + residual_ratio
        lead = _lead(ref, values, lead_window)
        if by_sim >= RESPONSE_MIN_R2 and added < allowed * by_sim:
            # Ahead of the measured signal it acts on it (a pedal); the simulation reproduces
            # it through the model's inputs all the same, so it is no effect the model lacks.
            reason = "follows" if lead * dt < RESPONSE_MIN_LEAD_S - 0.5 * dt else "reproduced"
            echoes.append(
                Response(name, kind, reason, by_sim, max(added, 0.0), lead * dt, explains)
            )
        else:
            kept.append((name, kind, values))
    return kept, tuple(echoes)


def _lead(ref: FloatArray, values: FloatArray, window: int) -> int:
    """Samples by which ``values`` leads the measured signal at the peak of their
    |cross-correlation| within ±``window``. Taken against the measured signal: the simulation
    is driven by logged inputs (a speed) that themselves follow the driver, so its timing says
    nothing of which way a channel acts."""
    if not _varies(ref):
        return 0
    # The direction of the peak |correlation|: a voltage falls as the power rises.
    sign = 1.0 if dot(values - float(np.mean(values)), ref - float(np.mean(ref))) >= 0 else -1.0
    return search_lag(ref, sign * values, window).lag


def _echo_share(
    x: FloatArray, ref: FloatArray, sim: FloatArray, floor: float = ECHO_MIN_R2
) -> float:
    """The share of x's variance the measured signal explains when x is an echo of it (at
    least ``floor``, and the simulated signal explains at least :data:`ECHO_SIMULATED_RATIO`
    of that), else 0."""
    if x.shape[0] < 3 or not _varies(x):
        return 0.0
    by_ref = _full_rate_r2(x, [ref])
    if by_ref < floor or _full_rate_r2(x, [sim]) < ECHO_SIMULATED_RATIO * by_ref:
        return 0.0
    return by_ref
