"""The pass over each distinct signal on the scoring threads, and the registered characteristics.

One pass per signal gives the core's fused characteristics (λ1–λ6 and the physical errors) and,
while the signal is fresh in cache, its local sums, standard metrics, fine-block sums for the
intervals, figure data and u-pooling distribution. A user's registered characteristics run
after it, one signal after another.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ..core.characteristics import SignalCharacteristics, signal_characteristics
from ..core.registry import Characteristic, compute_characteristic
from ..core.uncertainty import BlockSums, block_sums_many, block_sums_stacked
from ..core.upooling import u_distribution_of
from ..data.align import AlignedData
from ..errors import CharacteristicError, DegenerateSignalError, HevvalError
from ..results.local_tables import LocalResult
from ..spec.model import SignalSpec, Spec
from .local import Labels, LocalSums, local_results, local_sums
from .signal_arrays import SignalArrays, Signature
from .threads import per_item, scoring_threads

__all__ = [
    "Scored",
    "SignalPass",
    "fused_characteristics",
    "interval_block_sums",
    "registered_characteristics",
]

if TYPE_CHECKING:
    from ..core.standard._moments import Moments

FloatArray = npt.NDArray[np.float64]


Scored = tuple[float, dict[str, float]]


@dataclass
class SignalPass:
    """What one distinct signal's pass on its scoring thread found."""

    characteristics: dict[Signature, SignalCharacteristics] = field(default_factory=dict)
    local: dict[Signature, LocalResult] = field(default_factory=dict)
    #: The standard metrics: value and components by name.
    standard: dict[Signature, dict[str, Scored]] = field(default_factory=dict)
    #: Fine-block sums for the intervals, of records not summed as a stack.
    blocks: dict[Signature, BlockSums] = field(default_factory=dict)
    #: The report's figure data, when asked for.
    figures: dict[Signature, dict[str, Any]] = field(default_factory=dict)
    #: A campaign recording's u-pooling distributions.
    u_distributions: dict[Signature, list[float]] = field(default_factory=dict)


def fused_characteristics(
    spec: Spec,
    unique: dict[Signature, SignalSpec],
    values: SignalArrays,
    dt: float,
    workers: int | None,
    labels: Labels | None,
    intervals: bool = False,
    figures_of: AlignedData | None = None,
) -> SignalPass:
    """λ1–λ6 and the physical errors of each distinct signal, from the core's fused pass, and
    with ``labels`` the signal over the spec's windows, phases, conditions and cells: the same
    pass sums them, and the tables' λ come from one vectorised call for all signals after the
    pass (a call per signal took turns at the interpreter with the other threads). The spec's
    standard metrics are scored on the same thread, those built on moments from the pass's
    sums, and with ``intervals`` the fine-block sums of a record not summed as a stack
    (``block_sums_stacked``) are taken there too, while the signal is fresh in cache; so are
    the figures (with ``figures_of``, the grid they are drawn on) and a campaign recording's u
    distributions. Nothing else reads the signals' arrays unless asked, so a column put on the
    grid here (``SignalArrays``) goes into a buffer the thread keeps for its next signal."""
    n_workers = scoring_threads(workers)
    metrics = [c for c in spec.characteristics() if c.compute is not None and c.standard]
    if metrics:
        # Only then: the standard metrics' package imports scipy.signal, a tenth of a second.
        from ..core.standard._moments import moments_from_pass
    found = SignalPass()
    buffers = threading.local()
    local: dict[Signature, LocalSums] = {}

    def score(item: tuple[Signature, SignalSpec]) -> HevvalError | None:
        signature, node = item
        ref, sim = values.pair(signature, buffers)
        group_runs = labels.grouping.runs(ref, sim) if labels is not None else None
        try:
            chars = signal_characteristics(
                ref,
                sim,
                dt=dt,
                max_lag_s=spec.alignment.max_lag_s,
                correlation=spec.correlation,
                reference_range=node.reference_range,
                workers=1 if len(unique) > 1 else n_workers,
                group_runs=group_runs,
            )
        except DegenerateSignalError as exc:
            return exc.with_context(line=node.line, key=node.key)
        if metrics and chars.sums is not None:
            moments = moments_from_pass(chars.sums, ref, sim)
            try:
                found.standard[signature] = _characteristics_of(
                    metrics, node, ref, sim, dt, moments
                )
            except HevvalError as exc:
                return exc
        if labels is not None:
            local[signature] = local_sums(labels, ref, sim, chars.reference_range, chars.group_sums)
        if intervals and not block_sums_stacked(int(ref.shape[0])):
            found.blocks[signature] = block_sums_many([(ref, sim)])[0]
        if figures_of is not None:
            found.figures[signature] = _figures(ref, sim, chars, figures_of)
        if spec.campaign is not None:
            u_distribution = _u_distribution(ref, sim)
            if u_distribution is not None:
                found.u_distributions[signature] = u_distribution
        # The sums have served: a spec keeps its signals' characteristics to the end.
        found.characteristics[signature] = replace(chars, sums=None, group_sums=None)
        return None

    # Each thread writes its own signals' entries; the errors are raised in signal order.
    for error in per_item(score, list(unique.items()), n_workers):
        if error is not None:
            raise error
    found.characteristics = {s: found.characteristics[s] for s in unique}
    if labels is not None:
        found.local = dict(
            zip(local, local_results(labels, list(local.values()), spec.correlation), strict=True)
        )
    return found


def registered_characteristics(
    spec: Spec,
    unique: dict[Signature, SignalSpec],
    values: Mapping[Signature, tuple[FloatArray, FloatArray]],
    dt: float,
    standard: Mapping[Signature, Mapping[str, Scored]],
) -> dict[Signature, dict[str, Scored]]:
    """Each distinct signal's registered (non-built-in) characteristics: value and components.

    The standard metrics come scored from the fused pass's threads (``standard``); a user's
    ``compute`` runs here, one signal after another, as its author may expect.
    """
    wanted = [c for c in spec.characteristics() if c.compute is not None]
    users = [c for c in wanted if not c.standard]
    out: dict[Signature, dict[str, Scored]] = {}
    for signature, node in unique.items():
        found = dict(standard.get(signature, {}))
        if users:
            ref, sim = values[signature]
            found.update(_characteristics_of(users, node, ref, sim, dt))
        out[signature] = {c.name: found[c.name] for c in wanted}
    return out


def _characteristics_of(
    characteristics: list[Characteristic],
    node: SignalSpec,
    ref: FloatArray,
    sim: FloatArray,
    dt: float,
    moments: Moments | None = None,
) -> dict[str, Scored]:
    """``characteristics`` of one signal pair, an error naming the signal's spec line."""
    out: dict[str, Scored] = {}
    for characteristic in characteristics:
        try:
            scored = compute_characteristic(characteristic, ref, sim, dt, moments)
        except CharacteristicError as exc:
            raise CharacteristicError(
                f"{exc.problem} for signal {node.name!r}",
                line=node.line,
                key=node.key,
                hint=exc.hint,
            ) from None
        except Exception as exc:
            raise CharacteristicError(
                f"characteristic {characteristic.name!r} failed on signal {node.name!r}: "
                f"{type(exc).__name__}: {exc}",
                line=node.line,
                key=node.key,
                hint="fix its compute(ref, sim, dt) function",
            ) from exc
        out[characteristic.name] = (scored.value, dict(scored.components))
    return out


def _figures(
    ref: FloatArray, sim: FloatArray, chars: SignalCharacteristics, aligned: AlignedData
) -> dict[str, Any]:
    from ..core.figures import figure_data

    return figure_data(
        ref,
        sim,
        dt=aligned.grid.dt,
        start_s=aligned.grid.start_s,
        max_lag=chars.lag_search.max_lag if chars.lag_search else 0,
        # About one point per pixel of the page's plots; the JSON stays half the size.
        points=1000,
        search=chars.lag_search,
    )


def _u_distribution(ref: FloatArray, sim: FloatArray) -> list[float] | None:
    """A campaign signal's u-pooling distribution (its finite samples), if it has any."""
    finite = np.isfinite(ref)
    if finite.any() and np.isfinite(sim).any():
        return [float(x) for x in u_distribution_of(ref[finite], sim[np.isfinite(sim)])]
    return None


def interval_block_sums(
    values: Mapping[Signature, tuple[FloatArray, FloatArray]], workers: int | None
) -> dict[Signature, BlockSums]:
    """Each distinct signal's sums over consecutive fine blocks, for its bootstrap intervals.

    The signals are summed as stacks, one stack per scoring thread.
    """
    if not values:
        return {}
    signatures = list(values)
    threads = max(1, min(scoring_threads(workers), len(signatures)))
    size = -(-len(signatures) // threads)
    shares = [signatures[i : i + size] for i in range(0, len(signatures), size)]

    def sums(share: list[Signature]) -> list[tuple[Signature, BlockSums]]:
        found = block_sums_many([values[signature] for signature in share])
        return list(zip(share, found, strict=True))

    return dict(pair for share in per_item(sums, shares, threads) for pair in share)
