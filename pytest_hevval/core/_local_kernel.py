"""The compiled pass behind :func:`pytest_hevval.core.local.labelled_sums` (needs numba).

Imported only when numba is installed and the record is long enough for the kernel to pay for
itself. One sequential loop per signal keeps the sums bit-for-bit repeatable; signals run in
parallel on the engine's threads, since the kernel releases the GIL.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt


@numba.njit(cache=True, nogil=True)
def _grouped(
    r: npt.NDArray[np.float64],
    s: npt.NDArray[np.float64],
    labels: npt.NDArray[np.int64],
    shift: float,
    out: npt.NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
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
                out[current, 0] += a0
                out[current, 1] += a1
                out[current, 2] += a2
                out[current, 3] += a3
                out[current, 4] += a4
                out[current, 5] += a5
                out[current, 6] += a6
                out[current, 7] += a7
                out[current, 8] += a8
                out[current, 9] += a9
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
        out[current, 0] += a0
        out[current, 1] += a1
        out[current, 2] += a2
        out[current, 3] += a3
        out[current, 4] += a4
        out[current, 5] += a5
        out[current, 6] += a6
        out[current, 7] += a7
        out[current, 8] += a8
        out[current, 9] += a9


def grouped_table(
    r: npt.NDArray[np.float64],
    s: npt.NDArray[np.float64],
    labels: npt.NDArray[np.int64],
    groups: int,
    shift: float,
) -> npt.NDArray[np.float64]:
    """The (groups, 10) table of sums in the order of ``core.local.SUM_COLUMNS``."""
    out = np.zeros((groups, 10), dtype=np.float64)
    _grouped(r, s, labels, shift, out)
    return out
