"""The one pipeline: specs in, evaluations out.

``pytest --hevval`` (one spec per item file, on each xdist worker), ``hevval run``,
``hevval diagnose`` and the Dask path all score specs through :func:`run_specs`, with the
settings of one :class:`RunOptions`. So a spec scored from the command line and from pytest
gives the same result and the same history record, apart from the run's own metadata.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from ..data.digest import DEFAULT_HASH
from ..data.remote import relative_to
from ..errors import HevvalError
from ..results.spec_result import SpecResult
from ..spec.model import Spec
from .cluster import error_from_payload, evaluate_on_dask, is_error_payload
from .diagnosis import diagnose_failures
from .engine import DataCache, Evaluation, evaluate_spec

__all__ = ["RunOptions", "run_specs"]

Outcome = Evaluation | HevvalError


@dataclass(frozen=True)
class RunOptions:
    """How specs are scored; parsed once from pytest's options or the command line."""

    #: The project root: model callables import from here; result paths are relative to it.
    rootdir: Path
    #: Keep figure data in the results (the HTML report needs it).
    figures: bool = False
    #: Keep the aligned arrays of every signal (diagnosis needs them).
    keep_arrays: bool = False
    #: Threads that score one spec's signals; None is the engine's default.
    workers: int | None = None
    #: A dask.distributed scheduler address (or "local"): score the specs there.
    dask: str | None = None
    #: How data files are identified in results: "fast" or "sha256" (see digest.py).
    data_hash: str = DEFAULT_HASH
    #: Give every λ and Φ its bootstrap interval (core/uncertainty.py).
    intervals: bool = True
    #: Diagnose the failing signals ("failed"), every signal ("all") or none ("off"), right
    #: after each spec is scored; the aligned data is then let go unless ``keep_arrays``.
    diagnose: str = "off"


def _relative_result(result: SpecResult, rootdir: Path) -> SpecResult:
    """Results name files relative to the root, so records move between machines."""

    def relative(path: str) -> str:
        return relative_to(rootdir, path)

    return replace(
        result,
        spec=relative(result.spec),
        data=result.data.with_paths(relative),
        campaign=result.campaign.with_paths(relative) if result.campaign else None,
    )


def run_specs(
    specs: Sequence[Spec],
    options: RunOptions,
    *,
    cache: DataCache | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[Outcome]:
    """Score every spec; one outcome per spec, in order.

    An outcome is an :class:`Evaluation` or the :class:`HevvalError` a user can fix (a bad
    spec or unreadable data), so one bad spec never hides the others' results. ``progress``
    is called with the number of specs done so far.
    """
    if options.dask:
        outcomes = _on_dask(specs, options, progress)
        for outcome in outcomes:
            _finish(outcome, options)
        return outcomes
    shared = cache if cache is not None else DataCache(options.data_hash)
    for spec in specs:
        shared.declare_spec(spec)
    outcomes = []
    for done, spec in enumerate(specs, start=1):
        outcome = _evaluate(spec, options, shared)
        # Right away: the aligned data are let go before the next spec is read. Diagnosed
        # first: the diagnosis reads the reference's other channels through the cache.
        _finish(outcome, options)
        shared.release_spec(spec)
        outcomes.append(outcome)
        if progress is not None:
            progress(done)
    return outcomes


def _finish(outcome: Outcome, options: RunOptions) -> None:
    """Paths relative to the root; the failing signals diagnosed where the data are here
    (not after a Dask worker scored the spec); the aligned data released unless kept."""
    if not isinstance(outcome, Evaluation):
        return
    outcome.result = _relative_result(outcome.result, options.rootdir)
    if options.diagnose != "off":
        outcome.diagnoses = diagnose_failures(outcome, options.diagnose, options.workers)
    if not options.keep_arrays:
        outcome.arrays = {}
        outcome.aligned = None


def _evaluate(spec: Spec, options: RunOptions, cache: DataCache) -> Outcome:
    try:
        return evaluate_spec(
            spec,
            cache=cache,
            rootdir=options.rootdir,
            figures=options.figures,
            keep_arrays=options.keep_arrays or options.diagnose != "off",
            workers=options.workers,
            intervals=options.intervals,
        )
    except HevvalError as exc:
        return exc


def _on_dask(
    specs: Sequence[Spec], options: RunOptions, progress: Callable[[int], None] | None
) -> list[Outcome]:
    assert options.dask is not None
    payloads = evaluate_on_dask(
        [Path(s.key) for s in specs],
        options.dask,
        rootdir=options.rootdir,
        figures=options.figures,
        progress=progress,
        threads_per_spec=options.workers,
        data_hash=options.data_hash,
        intervals=options.intervals,
    )
    return [
        error_from_payload(payload)
        if is_error_payload(payload)
        else Evaluation(spec, SpecResult.from_dict(payload), None)
        for spec, payload in zip(specs, payloads, strict=True)
    ]
