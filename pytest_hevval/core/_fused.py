"""The compiled loops behind :mod:`pytest_hevval.core.kernel` (imports numba; load it lazily).

Each parallel loop writes one row of partial results per chunk; the caller combines the rows
in chunk order, so a result depends on the chunk size but not on the thread count. Every
function is called with one set of argument types (C-contiguous float64 arrays, float64
scalars, int64 counts), so each compiles once and its cache holds one entry.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .kernel import (
    ABS_ERROR,
    CROSS,
    ERROR_M2,
    ERROR_SUM,
    FIELDS,
    REF_MAX,
    REF_MIN,
    REF_SQ,
    REF_SUM,
    SIGN_MATCHES,
    SIM_MAX,
    SIM_MIN,
    SIM_SQ,
    SIM_SUM,
    SQ_ERROR,
    N,
)

# Reassociation lets LLVM vectorise the sums; no-NaN lets it drop the NaN cases of the
# comparisons. NaN input still poisons the sums of squares, which the caller checks before
# trusting an extreme.
_FAST = {"reassoc", "contract", "nnan", "nsz"}


@numba.njit(cache=True)
def _quarter_means(x, start, stop, scale, quarter, sixteenth):  # type: ignore[no-untyped-def]
    """Block means by 4 and 16 of x[start:stop]·scale, summed in the numpy path's order.

    Compiled without reassociation: ((a + b) + (c + d))·0.25 here is bit-identical to the
    strided pairwise additions of characteristics._quarter_means.
    """
    q0 = start // 4
    quarters = (stop - start) // 4
    for q in range(quarters):
        i = start + 4 * q
        a = x[i] * scale
        b = x[i + 1] * scale
        c = x[i + 2] * scale
        d = x[i + 3] * scale
        quarter[q0 + q] = ((a + b) + (c + d)) * 0.25
    h0 = start // 16
    for h in range(quarters // 4):
        j = q0 + 4 * h
        sixteenth[h0 + h] = (
            (quarter[j] + quarter[j + 1]) + (quarter[j + 2] + quarter[j + 3])
        ) * 0.25


@numba.njit(cache=True, fastmath=_FAST)
def _chunk_row(ref, sim, start, stop, scale, row):  # type: ignore[no-untyped-def]
    """The sums of one chunk, in three loops over it while it is in cache.

    Loops index slice views from zero: an index that may be negative makes numba check for
    wraparound, which stops LLVM from vectorising the loop.
    """
    n_total = ref.shape[0]
    m = stop - start
    ref_part = ref[start:stop]
    sim_part = sim[start:stop]
    abs_error = 0.0
    sq_error = 0.0
    error_sum = 0.0
    ref_sum = 0.0
    sim_sum = 0.0
    ref_sq = 0.0
    sim_sq = 0.0
    cross = 0.0
    for i in range(m):
        r = ref_part[i] * scale
        s = sim_part[i] * scale
        e = r - s
        error_sum += e
        sq_error += e * e
        abs_error += abs(e)
        ref_sum += r
        sim_sum += s
        ref_sq += r * r
        sim_sq += s * s
        cross += r * s
    # The simulated extremes are left to the caller, which rarely needs them; min and max
    # do not vectorise here and cost as much as all the sums above.
    ref_min = math.inf
    ref_max = -math.inf
    for i in range(m):
        r = ref_part[i] * scale
        ref_min = min(ref_min, r)
        ref_max = max(ref_max, r)
    error_mean = error_sum / m
    if error_mean * error_sum <= 0.5 * sq_error:
        # As in the numpy path: Σe² − (Σe)²/m loses at most a bit when spread ≥ bias.
        error_m2 = sq_error - error_mean * error_sum
    else:
        error_m2 = 0.0
        for i in range(m):
            d = (ref_part[i] * scale - sim_part[i] * scale) - error_mean
            error_m2 += d * d
    # Central differences: the first and last sample of the record have derivative 0, and
    # those endpoints always agree. Comparing the neighbours gives the sign of the difference.
    first = max(start, 1)
    last = min(stop, n_total - 1)
    matches = 0
    if last > first:
        r_before = ref[first - 1 : last - 1]
        r_after = ref[first + 1 : last + 1]
        s_before = sim[first - 1 : last - 1]
        s_after = sim[first + 1 : last + 1]
        for j in range(last - first):
            a = r_after[j]
            b = r_before[j]
            c = s_after[j]
            d = s_before[j]
            matches += ((a > b) == (c > d)) & ((a < b) == (c < d))
    if start == 0:
        matches += 1
    if stop == n_total and n_total > 1:
        matches += 1
    row[N] = m
    row[ABS_ERROR] = abs_error
    row[SQ_ERROR] = sq_error
    row[ERROR_SUM] = error_sum
    row[ERROR_M2] = error_m2
    row[REF_SUM] = ref_sum
    row[SIM_SUM] = sim_sum
    row[REF_SQ] = ref_sq
    row[SIM_SQ] = sim_sq
    row[CROSS] = cross
    row[REF_MIN] = ref_min
    row[REF_MAX] = ref_max
    row[SIM_MIN] = math.inf
    row[SIM_MAX] = -math.inf
    row[SIGN_MATCHES] = matches


@numba.njit(parallel=True, cache=True)
def main_pass(ref, sim, scale, chunk, ref4, sim4, ref16, sim16):  # type: ignore[no-untyped-def]
    """One row of sums per chunk of ``chunk`` samples (a multiple of 16).

    The block means by 4 and 16 are written into ref4 … sim16 unless they are empty.
    """
    n = ref.shape[0]
    chunks = (n + chunk - 1) // chunk
    rows = np.empty((chunks, FIELDS), dtype=np.float64)
    levels = ref4.shape[0] > 0
    for c in numba.prange(chunks):
        start = c * chunk
        stop = min(start + chunk, n)
        _chunk_row(ref, sim, start, stop, scale, rows[c])
        if levels:
            _quarter_means(ref, start, stop, scale, ref4, ref16)
            _quarter_means(sim, start, stop, scale, sim4, sim16)
    return rows


@numba.njit(cache=True, fastmath=_FAST)
def _window_row(r, s, a, b, lo, count, r_mean, s_mean, scale, row):  # type: ignore[no-untyped-def]
    width = b - a
    s_part = s[a:b]
    r_part = r[a + lo : b + lo + count - 1]
    centred_s = np.empty(width, dtype=np.float64)
    centred_r = np.empty(width + count - 1, dtype=np.float64)
    for j in range(width):
        centred_s[j] = (s_part[j] - s_mean) * scale
    for j in range(width + count - 1):
        centred_r[j] = (r_part[j] - r_mean) * scale
    # Four lags per sweep: each centred simulated sample is loaded once for all four.
    k = 0
    while k + 4 <= count:
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        t3 = 0.0
        shifted = centred_r[k:]
        for j in range(width):
            x = centred_s[j]
            t0 += shifted[j] * x
            t1 += shifted[j + 1] * x
            t2 += shifted[j + 2] * x
            t3 += shifted[j + 3] * x
        row[k] = t0
        row[k + 1] = t1
        row[k + 2] = t2
        row[k + 3] = t3
        k += 4
    while k < count:
        total = 0.0
        shifted = centred_r[k:]
        for j in range(width):
            total += shifted[j] * centred_s[j]
        row[k] = total
        k += 1
    energy = 0.0
    for j in range(width):
        energy += centred_r[j] * centred_r[j]
    row[count] = energy


@numba.njit(parallel=True, cache=True)
def lag_window(r, s, lo, count, r_mean, s_mean, scale, core_lo, core_hi, chunk):  # type: ignore[no-untyped-def]
    """Per chunk of the window [core_lo, core_hi): C(lo + k) for k < count, then the energy
    Σ ((r[j] − μ)·scale)² over the chunk shifted by ``lo``."""
    chunks = (core_hi - core_lo + chunk - 1) // chunk
    rows = np.empty((chunks, count + 1), dtype=np.float64)
    for c in numba.prange(chunks):
        a = core_lo + c * chunk
        b = min(a + chunk, core_hi)
        _window_row(r, s, a, b, lo, count, r_mean, s_mean, scale, rows[c])
    return rows


@numba.njit(parallel=True, cache=True)
def interpolate(values, index, right, offset, step, exact):  # type: ignore[no-untyped-def]
    """values at the grid points of a plan (data/align.py), as np.interp rounds them.

    Compiled without fast-math: the same operations in the same order as np.interp, so the
    result is bit-identical to the numpy path.
    """
    n = index.shape[0]
    out = np.empty(n, dtype=np.float64)
    for i in numba.prange(n):
        left = values[index[i]]
        if exact[i]:
            out[i] = left
        else:
            out[i] = (values[right[i]] - left) / step[i] * offset[i] + left
    return out


# -- sums per group (windows, phases, conditions, region cells) ---------------------------


@numba.njit(cache=True, inline="always")
def _flush(out, row, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9):  # type: ignore[no-untyped-def]
    """Adds one run's sums to its group's row."""
    out[row, 0] += a0
    out[row, 1] += a1
    out[row, 2] += a2
    out[row, 3] += a3
    out[row, 4] += a4
    out[row, 5] += a5
    out[row, 6] += a6
    out[row, 7] += a7
    out[row, 8] += a8
    out[row, 9] += a9


@numba.njit(cache=True, nogil=True)
def grouped_sums(r, s, labels, shift, out):  # type: ignore[no-untyped-def]
    """Adds the ``core.local.SUM_COLUMNS`` of every labelled sample to its group's row."""
    # Labels come in long runs (a window, a stretch in one cell), so the sums stay in
    # registers for a run and go to the table when the label changes.
    n = r.shape[0]
    if n == 0:
        return
    current = labels[0]
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = 0.0
    for i in range(n):
        g = labels[i]
        if g != current:
            if current >= 0:
                _flush(out, current, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9)
            a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = 0.0
            current = g
        if g < 0:
            continue
        ri = r[i]
        si = s[i]
        e = ri - si
        d = e - shift
        a0 += 1.0
        a1 += d
        a2 += d * d
        a3 += abs(e)
        a4 += ri
        a5 += si
        a6 += ri * ri
        a7 += si * si
        a8 += ri * si
        if 0 < i < n - 1:
            dr = r[i + 1] - r[i - 1]
            ds = s[i + 1] - s[i - 1]
            if ((dr > 0) - (dr < 0)) == ((ds > 0) - (ds < 0)):
                a9 += 1.0
        else:
            a9 += 1.0
    if current >= 0:
        _flush(out, current, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9)
