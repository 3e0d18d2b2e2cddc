"""Hypothesis strategies shared by the tests of the maths."""

from __future__ import annotations

import numpy as np
from hypothesis import assume
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

__all__ = ["finite", "signal_pairs"]

#: Finite sample values over twelve orders of magnitude.
finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@st.composite
def signal_pairs(
    draw: st.DrawFn, min_size: int = 3, max_size: int = 300
) -> tuple[np.ndarray, np.ndarray]:
    """An aligned (reference, simulated) pair whose reference is not constant."""
    n = draw(st.integers(min_size, max_size))
    reference = draw(hnp.arrays(np.float64, n, elements=finite))
    assume(np.ptp(reference) > 1e-6 * (np.abs(reference).max() + 1))
    simulated = draw(hnp.arrays(np.float64, n, elements=finite))
    return reference, simulated
