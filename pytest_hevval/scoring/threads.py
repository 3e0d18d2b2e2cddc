"""The threads one spec's signals are scored and diagnosed on.

numpy's loops and the compiled kernel release the GIL, so a few threads score signals side by
side; one place says how many and maps work over them in order.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ["per_item", "scoring_threads"]

T = TypeVar("T")


R = TypeVar("R")


def scoring_threads(workers: int | None) -> int:
    """Threads a spec's signals are scored (and its failing signals diagnosed) on: as asked,
    else up to two."""
    return workers if workers is not None else min(2, os.cpu_count() or 1)


def per_item(score: Callable[[T], R], items: list[T], threads: int) -> list[R]:
    """``score`` of every item in order, on ``threads`` threads when there is more than one.

    numpy's loops and the compiled kernel release the GIL, so signals score side by side.
    """
    if threads > 1 and len(items) > 1:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            return list(pool.map(score, items))
    return [score(item) for item in items]
