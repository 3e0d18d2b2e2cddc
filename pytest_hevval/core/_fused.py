"""The compiled loops behind :mod:`pytest_hevval.core.kernel` (imports numba; load it lazily).

Each loop covers a range of chunks and writes one row of partial results per chunk, without
holding the GIL; the caller runs contiguous ranges on its threads and combines the rows in
chunk order, so a result depends on the chunk size but not on the thread count. Every
function is called with one set of argument types (C-contiguous float64 arrays, float64
scalars, int64 counts), so each compiles once and its cache holds one entry.

Literals: numba compiles a callee once per literal argument it is passed from compiled code
(``k = 0`` before a loop, a kind 0–3, a column number), each compile a tenth to a whole second
of a fresh install's first run. Counts and indices passed on are therefore wrapped in
``np.int64`` where they start as literals.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba.core import cgutils, types
from numba.extending import intrinsic

from .kernel import (
    ABS_ERROR,
    CROSS,
    ERROR_M2,
    ERROR_SUM,
    REF_MAX,
    REF_MIN,
    REF_SQ,
    REF_SUM,
    SIGN_MATCHES,
    SIM_SQ,
    SIM_SUM,
    SQ_ERROR,
    SQUARES_HIGH,
    SQUARES_LOW,
    N,
)

# Reassociation lets LLVM vectorise the sums; no-NaN lets it drop the NaN cases of the
# comparisons. NaN input still poisons the sums of squares, which the caller checks before
# trusting an extreme.
_FAST = {"reassoc", "contract", "nnan", "nsz"}
# For minima, maxima and counts over finite values (the caller checks): order-free, so
# reassociation changes nothing, and there is no NaN to keep.
_QUALITY_FAST = {"reassoc", "nnan", "nsz"}


def _minnum(typingctx, a, b):  # type: ignore[no-untyped-def]
    """llvm.minnum: the smaller of two floats, which LLVM vectorises as a reduction (a loop of
    ``min`` or of comparisons it does not)."""
    return _binary_intrinsic("llvm.minnum.f64")


def _maxnum(typingctx, a, b):  # type: ignore[no-untyped-def]
    """llvm.maxnum: the larger of two floats (see :func:`_minnum`)."""
    return _binary_intrinsic("llvm.maxnum.f64")


def _binary_intrinsic(name: str) -> tuple[Any, Any]:
    """The typing and code of a numba intrinsic calling LLVM's ``name`` on two float64."""
    signature = types.float64(types.float64, types.float64)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        double = ir.DoubleType()
        function = cgutils.get_or_insert_function(  # type: ignore[no-untyped-call]
            builder.module, ir.FunctionType(double, [double, double]), name
        )
        return builder.call(function, args)

    return signature, codegen


_fmin: Any = intrinsic(_minnum)
_fmax: Any = intrinsic(_maxnum)


@numba.njit(cache=True)
def _quarter_means(x, start, stop, scale, quarter, sixteenth, sixty_fourth):  # type: ignore[no-untyped-def]
    """Block means by 4, 16 and 64 of x[start:stop]·scale, summed in the numpy path's order
    (``start`` is a multiple of 64).

    Compiled without reassociation: ((a + b) + (c + d))·0.25 here is bit-identical to the
    strided pairwise additions of characteristics._quarter_means. Slice views indexed from zero
    let LLVM vectorise the loops; x·1.0 is x, so the common unscaled case skips the products.
    """
    q0 = start // 4
    quarters = (stop - start) // 4
    xs = x[start : start + 4 * quarters]
    out = quarter[q0 : q0 + quarters]
    if scale == 1.0:
        for q in range(quarters):
            out[q] = ((xs[4 * q] + xs[4 * q + 1]) + (xs[4 * q + 2] + xs[4 * q + 3])) * 0.25
    else:
        for q in range(quarters):
            a = xs[4 * q] * scale
            b = xs[4 * q + 1] * scale
            c = xs[4 * q + 2] * scale
            d = xs[4 * q + 3] * scale
            out[q] = ((a + b) + (c + d)) * 0.25
    h0 = start // 16
    sixteenths = quarters // 4
    top = sixteenth[h0 : h0 + sixteenths]
    for h in range(sixteenths):
        top[h] = ((out[4 * h] + out[4 * h + 1]) + (out[4 * h + 2] + out[4 * h + 3])) * 0.25
    g0 = start // 64
    sixty_fourths = sixteenths // 4
    coarse = sixty_fourth[g0 : g0 + sixty_fourths]
    for g in range(sixty_fourths):
        coarse[g] = ((top[4 * g] + top[4 * g + 1]) + (top[4 * g + 2] + top[4 * g + 3])) * 0.25


@numba.njit(cache=True, nogil=True)
def quarter_level(x, out, chunk, first, last):  # type: ignore[no-untyped-def]
    """Block means by 4 of x into out (len(x) // 4) for chunks [first, last) of ``chunk``
    samples, as lag._quarter_level sums them."""
    quarters = out.shape[0]
    per = chunk // 4
    for c in range(first, last):
        q0 = c * per
        q1 = min(q0 + per, quarters)
        xs = x[4 * q0 : 4 * q1]
        part = out[q0:q1]
        for q in range(q1 - q0):
            part[q] = ((xs[4 * q] + xs[4 * q + 1]) + (xs[4 * q + 2] + xs[4 * q + 3])) * 0.25


@numba.njit(cache=True, inline="always")
def _with_neighbours(x, first, last):  # type: ignore[no-untyped-def]
    """x[first:last] and the views one sample before and after it (0 < first ≤ last < n), each
    indexed from zero: an index that may be negative makes numba check for wraparound, which
    stops LLVM from vectorising the loop over them."""
    return x[first:last], x[first - 1 : last - 1], x[first + 1 : last + 1]


@numba.njit(cache=True, fastmath=_FAST)
def _chunk_row(ref, sim, start, stop, scale, row):  # type: ignore[no-untyped-def]
    """The sums of one chunk, in one loop over it (two when the error's bias dominates).

    The samples with both neighbours in the record carry the λ2 sign comparison in the same
    loop (over views from ``_with_neighbours``); the record's first and last sample
    (derivative 0 on both sides, so they always agree) are added after it.
    """
    n_total = ref.shape[0]
    m = stop - start
    first = max(start, 1)
    last = max(min(stop, n_total - 1), first)
    inner = last - first
    r_part, r_before, r_after = _with_neighbours(ref, first, last)
    s_part, s_before, s_after = _with_neighbours(sim, first, last)
    abs_error = 0.0
    sq_error = 0.0
    error_sum = 0.0
    ref_sum = 0.0
    sim_sum = 0.0
    ref_sq = 0.0
    sim_sq = 0.0
    cross = 0.0
    ref_min = math.inf
    ref_max = -math.inf
    matches = 0
    for i in range(inner):
        r = r_part[i] * scale
        s = s_part[i] * scale
        e = r - s
        error_sum += e
        sq_error += e * e
        abs_error += abs(e)
        ref_sum += r
        sim_sum += s
        ref_sq += r * r
        sim_sq += s * s
        cross += r * s
        # Only the reference's extremes (for R): the caller rarely needs the simulation's.
        ref_min = _fmin(ref_min, r)
        ref_max = _fmax(ref_max, r)
        # The sign of a central difference, from comparing the neighbours.
        a = r_after[i]
        b = r_before[i]
        c = s_after[i]
        d = s_before[i]
        matches += ((a > b) == (c > d)) & ((a < b) == (c < d))
    # The record's ends: no sign comparison, they always agree.
    for i in (0, n_total - 1):
        if start <= i < stop and not first <= i < last:
            r = ref[i] * scale
            s = sim[i] * scale
            e = r - s
            error_sum += e
            sq_error += e * e
            abs_error += abs(e)
            ref_sum += r
            sim_sum += s
            ref_sq += r * r
            sim_sq += s * s
            cross += r * s
            ref_min = _fmin(ref_min, r)
            ref_max = _fmax(ref_max, r)
            matches += 1
    error_mean = error_sum / m
    if error_mean * error_sum <= 0.5 * sq_error:
        # As in the numpy path: Σe² − (Σe)²/m loses at most a bit when spread ≥ bias.
        error_m2 = sq_error - error_mean * error_sum
    else:
        error_m2 = 0.0
        ref_chunk = ref[start:stop]
        sim_chunk = sim[start:stop]
        for i in range(m):
            d = (ref_chunk[i] * scale - sim_chunk[i] * scale) - error_mean
            error_m2 += d * d
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
    row[SIGN_MATCHES] = matches


@numba.njit(cache=True, nogil=True)
def main_pass(  # type: ignore[no-untyped-def]
    ref, sim, scale, chunk, ref4, sim4, ref16, sim16, ref64, sim64, rows,
    starts, stops, run_group, shift, sums, first, last,
):  # fmt: skip
    """Rows of sums for chunks [first, last) of ``chunk`` samples (a multiple of 64).

    The block means by 4, 16 and 64 are written into ref4 … sim64 unless they are empty. The
    sums of the groups of the runs ``starts``, ``stops``, ``run_group`` (unscaled, about
    ``shift``) are added to their rows of ``sums`` while each chunk is in cache, unless there
    are no runs (see ``_grouped_span``; one range of chunks at a time, as the rows depend on
    the order).
    """
    n = ref.shape[0]
    levels = ref4.shape[0] > 0
    k = np.searchsorted(stops, first * chunk, side="right")
    for c in range(first, last):
        start = c * chunk
        stop = min(start + chunk, n)
        _chunk_row(ref, sim, start, stop, scale, rows[c])
        if levels:
            _quarter_means(ref, start, stop, scale, ref4, ref16, ref64)
            _quarter_means(sim, start, stop, scale, sim4, sim16, sim64)
        k = _grouped_span(ref, sim, start, stop, shift, starts, stops, run_group, k, sums)


#: Samples per tile of the lag window. Short tiles let the next tile's loads from memory
#: overlap the sweeps over this one: on 10^8 samples the whole window took 120 ms on one
#: thread with tiles of 128, against 126–138 ms with 256–512 and 173 ms with 1,024
#: (13 lags; 2^15 samples at once measured 1.3 ns a sample in cache, 1,024 1.0 ns).
_TILE = 128


@numba.njit(cache=True, fastmath=_FAST)
def _window_row(r, s, a, b, lo, count, r_mean, s_mean, scale, row):  # type: ignore[no-untyped-def]
    width = b - a
    centred_s = np.empty(_TILE, dtype=np.float64)
    centred_r = np.empty(_TILE + count - 1, dtype=np.float64)
    for k in range(count + 1):
        row[k] = 0.0
    for t in range(0, width, _TILE):
        w = min(_TILE, width - t)
        s_part = s[a + t : a + t + w]
        r_part = r[a + t + lo : a + t + w + lo + count - 1]
        for j in range(w):
            centred_s[j] = (s_part[j] - s_mean) * scale
        for j in range(w + count - 1):
            centred_r[j] = (r_part[j] - r_mean) * scale
        # Eight, then four lags per sweep: each centred simulated sample is loaded once for
        # all of them, and the lagged loads hit L1.
        k = 0
        energy = 0.0
        if count >= 8:
            # The first sweep also takes the reference energy of lag lo (its samples are
            # the ones it loads for t0).
            t0 = t1 = t2 = t3 = t4 = t5 = t6 = t7 = 0.0
            for j in range(w):
                x = centred_s[j]
                y = centred_r[j]
                energy += y * y
                t0 += y * x
                t1 += centred_r[j + 1] * x
                t2 += centred_r[j + 2] * x
                t3 += centred_r[j + 3] * x
                t4 += centred_r[j + 4] * x
                t5 += centred_r[j + 5] * x
                t6 += centred_r[j + 6] * x
                t7 += centred_r[j + 7] * x
            row[0] += t0
            row[1] += t1
            row[2] += t2
            row[3] += t3
            row[4] += t4
            row[5] += t5
            row[6] += t6
            row[7] += t7
            k = 8
        else:
            for j in range(w):
                energy += centred_r[j] * centred_r[j]
        while k + 8 <= count:
            t0 = t1 = t2 = t3 = t4 = t5 = t6 = t7 = 0.0
            shifted = centred_r[k:]
            for j in range(w):
                x = centred_s[j]
                t0 += shifted[j] * x
                t1 += shifted[j + 1] * x
                t2 += shifted[j + 2] * x
                t3 += shifted[j + 3] * x
                t4 += shifted[j + 4] * x
                t5 += shifted[j + 5] * x
                t6 += shifted[j + 6] * x
                t7 += shifted[j + 7] * x
            row[k] += t0
            row[k + 1] += t1
            row[k + 2] += t2
            row[k + 3] += t3
            row[k + 4] += t4
            row[k + 5] += t5
            row[k + 6] += t6
            row[k + 7] += t7
            k += 8
        while k + 4 <= count:
            t0 = t1 = t2 = t3 = 0.0
            shifted = centred_r[k:]
            for j in range(w):
                x = centred_s[j]
                t0 += shifted[j] * x
                t1 += shifted[j + 1] * x
                t2 += shifted[j + 2] * x
                t3 += shifted[j + 3] * x
            row[k] += t0
            row[k + 1] += t1
            row[k + 2] += t2
            row[k + 3] += t3
            k += 4
        while k < count:
            total = 0.0
            shifted = centred_r[k:]
            for j in range(w):
                total += shifted[j] * centred_s[j]
            row[k] += total
            k += 1
        row[count] += energy


@numba.njit(cache=True, nogil=True)
def lag_window(r, s, lo, count, r_mean, s_mean, scale, core_lo, core_hi, chunk, rows, first, last):  # type: ignore[no-untyped-def]
    """For chunks [first, last) of the window [core_lo, core_hi): C(lo + k) for k < count,
    then the energy Σ ((r[j] − μ)·scale)² over the chunk shifted by ``lo``."""
    for c in range(first, last):
        a = core_lo + c * chunk
        b = min(a + chunk, core_hi)
        _window_row(r, s, a, b, lo, count, r_mean, s_mean, scale, rows[c])


@numba.njit(cache=True, nogil=True)
def interpolate(values, index, offset, step, out, start, stop):  # type: ignore[no-untyped-def]
    """values at the grid points [start, stop) of a plan (data/align.py), as np.interp rounds
    them, written into out.

    A grid point that takes its left sample as it is carries offset −0.0 and step 1: its right
    neighbour is then the left one, and (left − left) / 1 · −0.0 + left is left to the bit
    (values are finite on this path). Every other point has a positive offset and reads the
    sample after its left one. No branch on the data, which has none to mispredict where time
    stamps fall on grid points at random; compiled without fast-math: the same operations in
    the same order as np.interp, so the result is bit-identical to the numpy path.
    """
    part = out[start:stop]
    where = index[start:stop]
    shift = offset[start:stop]
    width = step[start:stop]
    for i in range(stop - start):
        j = where[i]
        o = shift[i]
        left = values[j]
        part[i] = (values[j + (o != 0.0)] - left) / width[i] * o + left


# -- sums per group (windows, phases, conditions, region cells) ---------------------------


#: The grouped sums are reassociated, as the main pass is, so the loop over a run vectorises;
#: NaN keeps its meaning, so a NaN sample shows in the sums (the caller then finds the scale as
#: numpy does).
_GROUPED_FAST = {"reassoc", "contract", "nsz"}
#: Runs shorter than this are summed sample by sample, without the set-up of a vectorised loop.
_SHORT_RUN = 16


@numba.njit(cache=True, fastmath=_GROUPED_FAST, inline="always")
def _add_terms(sums, ri, si, r_before, r_after, s_before, s_after, shift):  # type: ignore[no-untyped-def]
    """``sums`` plus one sample's ``core.groups.SUM_COLUMNS`` but the count."""
    a1, a2, a3, a4, a5, a6, a7, a8, a9 = sums
    e = ri - si
    d = e - shift
    # No branch on the data: the signs of noisy signals agree at random.
    match = ((r_after > r_before) == (s_after > s_before)) & (
        (r_after < r_before) == (s_after < s_before)
    )
    return (
        a1 + d,
        a2 + d * d,
        a3 + abs(e),
        a4 + ri,
        a5 + si,
        a6 + ri * ri,
        a7 + si * si,
        a8 + ri * si,
        a9 + match,
    )


@numba.njit(cache=True, fastmath=_GROUPED_FAST)
def _grouped_span(r, s, lo, hi, shift, starts, stops, run_group, k, sums):  # type: ignore[no-untyped-def]
    """Adds the ``core.groups.SUM_COLUMNS`` of the samples in [lo, hi) to their groups' rows
    of ``sums``, run by run from run ``k`` (the first that ends after ``lo``); returns the
    first run that ends after ``hi``.

    The runs ``[starts[k], stops[k])`` of group ``run_group[k]`` come in sample order; samples
    between runs belong to no group. Each run's part of the span is summed on its own, then
    added to its group's row: the rows depend only on the spans, so the main pass (which calls
    this chunk by chunk while the chunk is in cache) and ``grouped_sums`` agree to the bit.
    """
    n = r.shape[0]
    runs = starts.shape[0]
    while k < runs and starts[k] < hi:
        a = max(starts[k], lo)
        b = min(stops[k], hi)
        # The samples with both neighbours in the record carry the λ2 sign comparison in a
        # loop that LLVM vectorises (see _with_neighbours). A short run (a noisy operating
        # variable changes cell every few samples) and the record's first and last sample go
        # sample by sample instead.
        if b - a < _SHORT_RUN:
            inner_lo = inner_hi = b
        else:
            inner_lo = max(a, 1)
            inner_hi = min(b, n - 1)
        rr, r_before, r_after = _with_neighbours(r, inner_lo, inner_hi)
        ss, s_before, s_after = _with_neighbours(s, inner_lo, inner_hi)
        sums9 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for j in range(inner_hi - inner_lo):
            sums9 = _add_terms(
                sums9, rr[j], ss[j], r_before[j], r_after[j], s_before[j], s_after[j], shift
            )
        for part in range(2):
            for i in range(a, inner_lo) if part == 0 else range(inner_hi, b):
                if 0 < i < n - 1:
                    sums9 = _add_terms(
                        sums9, r[i], s[i], r[i - 1], r[i + 1], s[i - 1], s[i + 1], shift
                    )
                else:  # the record's ends: a derivative of 0 on both sides, which agree
                    sums9 = _add_terms(sums9, r[i], s[i], 0.0, 0.0, 0.0, 0.0, shift)
        a1, a2, a3, a4, a5, a6, a7, a8, a9 = sums9
        if a < b:
            g = run_group[k]
            sums[g, 0] += b - a
            sums[g, 1] += a1
            sums[g, 2] += a2
            sums[g, 3] += a3
            sums[g, 4] += a4
            sums[g, 5] += a5
            sums[g, 6] += a6
            sums[g, 7] += a7
            sums[g, 8] += a8
            sums[g, 9] += a9
        if stops[k] > hi:
            break  # the run goes on into the next span
        k += 1
    return k


@numba.njit(cache=True, nogil=True)
def grouped_sums(r, s, starts, stops, run_group, shift, chunk, sums):  # type: ignore[no-untyped-def]
    """Adds every group's ``core.groups.SUM_COLUMNS`` to its row of ``sums``, chunk by chunk
    as the main pass does (see ``_grouped_span``)."""
    n = r.shape[0]
    k = np.int64(0)  # not a literal 0 (see the module docstring)
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        k = _grouped_span(r, s, start, stop, shift, starts, stops, run_group, k, sums)


# -- bootstrap fine blocks ------------------------------------------------------------------

_TOO_BIG = 2.0**400
_TOO_SMALL = 2.0**-400


@numba.njit(cache=True, fastmath=_FAST)
def _peak_magnitude(r, s):  # type: ignore[no-untyped-def]
    """The largest |value| of r and s (a maximum: the same in any order)."""
    peak = 0.0
    for j in range(r.shape[0]):
        peak = _fmax(peak, _fmax(abs(r[j]), abs(s[j])))
    return peak


@numba.njit(cache=True, fastmath=_FAST)
def _lag1_correlation(r, s, mean):  # type: ignore[no-untyped-def]
    """Lag-1 autocorrelation of the error r − s centred on ``mean``; 0 if constant.

    Reassociated so the sums vectorise: ρ only sets a block length, and a rounding-level
    difference from ``uncertainty.lag1_autocorrelation`` cannot move it but at a boundary.
    """
    n = r.shape[0]
    if n < 3:
        return 0.0
    first = r[0] - s[0]
    power = 0.0
    lagged = 0.0
    varies = False
    for j in range(1, n):
        e = r[j] - s[j]
        centred = e - mean
        before = r[j - 1] - s[j - 1] - mean
        power += centred * centred
        lagged += centred * before
        varies |= e != first
    if not varies:
        return 0.0
    power += (first - mean) * (first - mean)
    if power > 0.0 and math.isfinite(power):
        return lagged / power
    return 0.0


#: Samples per span of the fine-block pass at most: the ρ products are taken of a span while it
#: is in cache, right after its rows.
_FINE_SPAN = 1 << 15


@numba.njit(cache=True)
def _errors_into(r, s, lo, hi, out):  # type: ignore[no-untyped-def]
    """out[:hi − lo] = r[lo:hi] − s[lo:hi]."""
    now_r = r[lo:hi]
    now_s = s[lo:hi]
    for j in range(hi - lo):
        out[j] = now_r[j] - now_s[j]


@numba.njit(cache=True, fastmath=_GROUPED_FAST)
def _lagged_products(errors, m, shift):  # type: ignore[no-untyped-def]
    """Σ d_j·d_(j−1) over j in [1, m), d = errors − shift (reassociated: ρ only sets a block
    length).

    The errors come from memory: with fast-math, r − s − shift computed here could be
    reassociated into r − (s + shift), losing a shift far below r's ulp, and numba compiles a
    callee with its caller's fast-math flags, so a helper without them would not keep it.
    """
    now = errors[1:m]
    before = errors[0 : m - 1]
    lagged = 0.0
    for j in range(m - 1):
        lagged += (now[j] - shift) * (before[j] - shift)
    return lagged


@numba.njit(cache=True)
def _fine_rows(r, s, fine, starts, stops, run_group, shift, out):  # type: ignore[no-untyped-def]
    """The rows of ``fine_block_sums``, run by run (the fine blocks ``starts``, ``stops``,
    ``run_group``) as ``_grouped_span`` sums windows and cells; returns Σ d_j·d_(j−1) of the
    shifted errors d."""
    n = r.shape[0]
    # Spans of whole fine blocks, so a row never straddles two spans.
    span = max(1, _FINE_SPAN // fine) * fine
    errors = np.empty(span + 1, dtype=np.float64)
    lagged = 0.0
    k = np.int64(0)  # not a literal 0 (see the module docstring)
    for lo in range(0, n, span):
        hi = min(lo + span, n)
        k = _grouped_span(r, s, lo, hi, shift, starts, stops, run_group, k, out)
        # From the sample before the span: its product with the span's first.
        first = max(lo - 1, 0)
        _errors_into(r, s, first, hi, errors)
        lagged += _lagged_products(errors, hi - first, shift)
    return lagged


@numba.njit(cache=True)
def _clear(out):  # type: ignore[no-untyped-def]
    for row in range(out.shape[0]):
        for column in range(out.shape[1]):
            out[row, column] = 0.0


@numba.njit(cache=True)
def _error_totals(out):  # type: ignore[no-untyped-def]
    """Σ d, Σ d² and Σ r² + Σ s² over the rows of ``fine_block_sums``."""
    total = total_sq = power = 0.0
    for row in range(out.shape[0]):
        total += out[row, 1]
        total_sq += out[row, 2]
        power += out[row, 6] + out[row, 7]
    return total, total_sq, power


@numba.njit(cache=True, inline="always")
def _head_shift(r, s, shift_samples):  # type: ignore[no-untyped-def]
    """The mean of the first ``shift_samples`` errors."""
    head = min(shift_samples, r.shape[0])
    total = 0.0
    for j in range(head):
        total += r[j] - s[j]
    return total / head if head else 0.0


@numba.njit(cache=True, nogil=True)
def fine_block_sums(r, s, fine, starts, stops, run_group, shift_samples, out):  # type: ignore[no-untyped-def]
    """One signal's ``core.groups.SUM_COLUMNS`` over runs of ``fine`` samples (the fine blocks
    ``starts``, ``stops``, ``run_group``, given as the windows' runs are, so the loops compile
    once for both) into ``out`` (rows, 10); returns (1, shift, ρ), or (scale, 0, 0) when the
    values need a power-of-two scale: the caller then sums copies scaled by it
    (``kernel.fine_block_sums``), through the same signature.

    The scale is ``characteristics.power_of_two_scale`` of the peak magnitude; the shift is the
    mean of the first ``shift_samples`` errors. The rows are summed as the windows and cells
    are (``_grouped_span``: reassociated, so the loop over a block vectorises), and agree with
    the numpy pass's to rounding.

    One loop over the samples in the common case: the sum of squares tells whether the peak
    can ask for a scale (peak² ≤ Σx² ≤ n·peak²); only then is the peak found. ρ comes from the
    same spans' sums of the shifted errors unless their mean dwarfs their spread, when a
    second loop centres them first.
    """
    n = r.shape[0]
    shift = _head_shift(r, s, shift_samples)
    _clear(out)
    lagged = _fine_rows(r, s, fine, starts, stops, run_group, shift, out)
    total, total_sq, power = _error_totals(out)
    if not SQUARES_LOW * max(n, 1) < power < SQUARES_HIGH:
        peak = _peak_magnitude(r, s)
        if math.isfinite(peak) and (peak > _TOO_BIG or 0.0 < peak < _TOO_SMALL):
            return math.ldexp(1.0, min(-math.frexp(peak)[1], 1000)), 0.0, 0.0
    if n < 3:
        return 1.0, shift, 0.0
    offset = total / n
    mean = shift + offset
    if offset * total > 0.5 * total_sq:
        # The mean error dwarfs the spread: the one-loop sums would cancel.
        return 1.0, shift, _lag1_correlation(r, s, mean)
    # Centred on the mean instead of the shift: Σ(d−δ)² and Σ(d_j−δ)(d_(j−1)−δ), δ = Σd / n.
    d_first = r[0] - s[0] - shift
    d_last = r[n - 1] - s[n - 1] - shift
    spread = total_sq - offset * total
    centred_lagged = lagged - offset * (2.0 * total - d_first - d_last) + (n - 1) * offset * offset
    if spread > 0.0 and math.isfinite(spread):
        return 1.0, shift, centred_lagged / spread
    return 1.0, shift, 0.0


# -- data-quality scan ------------------------------------------------------------------------


# A step of zero weighs this much in the smallest step: more than any finite step, so only a
# channel whose every moving step overflows sees it (where 2 × it is inf, as 2 × inf is).
_NOT_MOVING = float(np.finfo(np.float64).max)


@numba.njit(cache=True, nogil=True, fastmath=_QUALITY_FAST)
def quality_steps(v):  # type: ignore[no-untyped-def]
    """(smallest step that moves, steps that do not move, max, min) of a finite channel, in
    one loop; the smallest step is inf without any that moves, and stands for every step's
    size only through twice its value (see ``_NOT_MOVING``).

    Minima, maxima and counts do not depend on the order they are taken in, so the loop is
    vectorised and still gives numpy's values; no step is NaN, since the values are finite.
    """
    n = v.shape[0]
    resolution = math.inf
    still = 0
    top = v[0]
    bottom = v[0]
    for i in range(n - 1):
        after = v[i + 1]
        change = abs(after - v[i])
        zero = change == 0.0
        still += zero
        resolution = _fmin(resolution, _fmax(change, _NOT_MOVING * zero))
        top = _fmax(top, after)
        bottom = _fmin(bottom, after)
    return resolution, still, top, bottom


@numba.njit(cache=True)
def _kept_pairs(kind, edges, flips, widen, time, seconds, out, count):  # type: ignore[no-untyped-def]
    """Rows (kind, start, final) of ``out`` for the runs [edges[0], edges[1]), [edges[2],
    edges[3]) … of the first ``flips`` edges that last ``seconds``; returns the new count.

    Called once per block, not once per run: a helper taking arrays, called per run, cost
    three times the loop that found the runs.
    """
    last = time.shape[0] - 1
    for e in range(0, flips - 1, 2):
        start = edges[e]
        final = min(edges[e + 1] - 1 + widen, last)
        if time[final] - time[start] >= seconds:
            if count < out.shape[0]:
                out[count, 0] = kind
                out[count, 1] = start
                out[count, 2] = final
            count += 1
    return count


@numba.njit(cache=True, inline="always")
def _in_run(kind, v, i, limit, value):  # type: ignore[no-untyped-def]
    """Whether index i of ``kind``'s mask is set (each caller passes a literal kind, so the
    other kinds' code folds away)."""
    if kind == 0:  # steps i and i + 1 both move, and their difference is within ``limit``
        step = v[i + 1] - v[i]
        following = v[i + 2] - v[i + 1]
        return (abs(following - step) <= limit) & (step != 0.0) & (following != 0.0)
    if kind == 1:  # step i is zero at a non-zero value
        after = v[i + 1]
        return (after - v[i] == 0.0) & (after != 0.0)
    return v[i] == value  # sample i is at ``value``


#: Mask entries looked at together: a block where no run starts or ends is passed over after
#: one vectorised count.
_RUN_BLOCK = 256


@numba.njit(cache=True, inline="always")
def _kind_runs(kind, v, m, widen, limit, value, time, seconds, out, count, edges):  # type: ignore[no-untyped-def]
    """The runs of ``kind``'s mask over [0, m) lasting ``seconds``, appended to ``out``."""
    inside = False
    for first in range(0, m, _RUN_BLOCK):
        last = min(first + _RUN_BLOCK, m)
        hits = 0
        for i in range(first, last):
            hits += _in_run(kind, v, i, limit, value)
        if hits == (last - first if inside else 0):
            continue
        # Where the mask flips, without a branch per entry (a noisy channel flips at random),
        # after the start of a run carried into the block, kept in edges[0].
        flips = 1 if inside else 0
        was = inside
        for i in range(first, last):
            now = _in_run(kind, v, i, limit, value)
            edges[flips] = i
            flips += now != was
            was = now
        count = _kept_pairs(
            np.int64(kind), edges, flips, np.int64(widen), time, seconds, out, np.int64(count)
        )  # not literals (see the module docstring)
        if flips % 2:  # a run goes on into the next block
            edges[0] = edges[flips - 1]
        inside = was
    if inside:
        edges[1] = m
        count = _kept_pairs(
            np.int64(kind), edges, np.int64(2), np.int64(widen), time, seconds, out, np.int64(count)
        )
    return count


@numba.njit(cache=True, nogil=True)
def quality_runs(v, time, limit, straight_s, flat_s, top, bottom, saturation_s, checks, out):  # type: ignore[no-untyped-def]
    """The runs of a finite channel that last long enough, as rows (kind, start, final) of
    ``out``, kind by kind, each in time order; returns how many there are (rows beyond ``out``
    are counted, not written).

    Kinds, each asked for by its bit of ``checks``: 0 steps that move and whose second
    difference is within ``limit`` (widened by 2 samples), 1 steps of zero at a non-zero value
    (widened by 1), 2 samples at ``top``, 3 samples at ``bottom``. The same comparisons as
    ``data.quality``'s numpy scan, so the same runs.
    """
    n = v.shape[0]
    edges = np.empty(_RUN_BLOCK + 1, dtype=np.int64)
    count = 0
    if checks & 1 and n > 2:
        count = _kind_runs(0, v, n - 2, 2, limit, 0.0, time, straight_s, out, count, edges)
    if checks & 2 and n > 1:
        count = _kind_runs(1, v, n - 1, 1, limit, 0.0, time, flat_s, out, count, edges)
    if checks & 4:
        count = _kind_runs(2, v, n, 0, limit, top, time, saturation_s, out, count, edges)
    if checks & 8:
        count = _kind_runs(3, v, n, 0, limit, bottom, time, saturation_s, out, count, edges)
    return count


@numba.njit(cache=True, nogil=True)
def dtw_path(x, y, band):  # type: ignore[no-untyped-def]
    """ISO/TS 18571's warping path of x onto y with |i − j| ≤ band: (rows, cols) from (0, 0).

    The compiled form of ``core.standard.iso18571._dtw_path``: the same recurrence and ties
    (up, then left, then diagonal), row by row where numpy goes diagonal by diagonal. Each D is
    gap·gap + best, rounded twice as numpy's square and sum are (no fastmath here: a fused
    multiply-add would round once), so both paths choose the same path among equal costs.
    """
    n = x.shape[0]
    width = 2 * band + 1
    choice = np.empty((n, width), dtype=np.int8)
    # Band cell k of a row at index k + 1, inf on both sides.
    previous = np.full(width + 2, np.inf)
    current = np.full(width + 2, np.inf)
    for i in range(n):
        lo = max(0, band - i)
        hi = min(width, n - i + band)
        current[lo] = np.inf
        current[hi + 1] = np.inf
        for k in range(lo, hi):
            gap = x[i] - y[i + k - band]
            up = previous[k + 2]
            left = current[k]
            diagonal = previous[k + 1]
            if i == 0 and k == lo:
                best = 0.0
                step = 0
            elif up <= left and up <= diagonal:
                best = up
                step = 0
            elif left <= diagonal:
                best = left
                step = 1
            else:
                best = diagonal
                step = 2
            current[k + 1] = gap * gap + best
            choice[i, k] = step
        previous, current = current, previous
    rows = np.empty(2 * n, dtype=np.int64)
    cols = np.empty(2 * n, dtype=np.int64)
    i = n - 1
    j = n - 1
    m = 0
    rows[0] = i
    cols[0] = j
    while i > 0 or j > 0:
        if i == 0:
            j -= 1
        elif j == 0:
            i -= 1
        else:
            step = choice[i, j - i + band]
            if step == 0:
                i -= 1
            elif step == 1:
                j -= 1
            else:
                i -= 1
                j -= 1
        m += 1
        rows[m] = i
        cols[m] = j
    return rows[m::-1].copy(), cols[m::-1].copy()
