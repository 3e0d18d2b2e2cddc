"""The model's side of a spec: exported files read, callables and FMUs run, their outputs checked.

What identifies the model in the result (path or callable, parameters, GUID) and what running it
cost (:class:`~pytest_hevval.results.runtime.ModelRuntime`) come from here too.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..data.record import Record, model_column_error
from ..data.remote import is_url
from ..errors import DataError
from ..results.runtime import ModelRuntime, RuntimeGate
from ..results.spec_facts import ModelData
from ..spec.model import SignalSpec, Spec
from .data_cache import DataCache
from .signal_arrays import columns_of

__all__ = ["check_model_columns", "check_model_output", "load_model"]


def check_model_output(spec: Spec) -> None:
    """A campaign recording whose exported model output is missing fails before its data are
    read, naming both files."""
    path = spec.model.path
    if spec.recording is None or spec.model.kind != "file" or path is None or is_url(path):
        return
    if not os.path.exists(path):
        raise DataError(
            f"recording {spec.recording!r} has no model output: the file does not exist "
            f"(its measured data: {spec.reference.path})",
            file=path,
            hint="export the model's run of this recording to that file, or drop the "
            "recording from the campaign",
        )


def load_model(
    spec: Spec, reference: Record, cache: DataCache, folders: list[Path]
) -> tuple[Record, ModelData, ModelRuntime | None]:
    """The model's output, what identifies the model, and what running it cost (None for
    exported files: they ran elsewhere)."""
    model = spec.model
    if model.kind == "file":
        record = cache.read(model, spec.model_columns())
        # The file's digest is computed while the spec is scored; spec_result waits for it.
        return record, ModelData(kind="file", path=model.path), None
    runs = [_run_model(spec, reference, folders) for _ in range(spec.runtime.repeat)]
    record = runs[0]
    info: ModelData
    if model.kind == "callable":
        from ..data.models import callable_identity

        identity = callable_identity(str(model.callable))
        info = ModelData(
            kind="callable",
            callable=model.callable,
            params=dict(model.params),
            module_file=identity.get("module_file"),
            module_sha256=identity.get("module_sha256"),
        )
    else:
        info = ModelData(
            kind="fmu",
            path=model.path,
            params=dict(model.params),
            guid=record.meta.get("guid") or None,
            # Outputs without numbers (text, bytes), left out when the spec names no outputs.
            unscored_outputs=dict(record.meta["unscored"]) if record.meta.get("unscored") else None,
        )
    costs = [run.meta["cost"] for run in runs]
    peaks = [c.peak_bytes for c in costs if c.peak_bytes is not None]
    time = next(iter(record.channels.values())).time if record.channels else None
    runtime = ModelRuntime(
        kind=model.kind,
        simulated_s=float(time[-1] - time[0]) if time is not None and time.size else 0.0,
        wall_s=tuple(c.wall_s for c in costs),
        cpu_s=tuple(c.cpu_s for c in costs),
        peak_memory_bytes=max(peaks) if peaks else None,
        steps=record.meta.get("steps"),
        events=record.meta.get("events"),
        gate=RuntimeGate(spec.runtime.min_realtime_factor, spec.runtime.max_s, spec.runtime.clock)
        if spec.runtime.gated
        else None,
    )
    return record, info, runtime


def _run_model(spec: Spec, reference: Record, folders: list[Path]) -> Record:
    """One run of a model that runs itself (a callable or an FMU) on ``reference``."""
    model = spec.model
    if model.kind == "callable":
        from ..data.models import run_callable

        inputs = spec.callable_inputs()
        try:
            return run_callable(
                str(model.callable),
                reference,
                inputs=inputs,
                params=dict(model.params),
                reference_time=spec.reference.options.time or "time",
                model_time=model.options.time or "time",
                folders=folders,
                spec_file=str(spec.path),
                options=model.options,
                scored=spec.scored_reference_columns(),
            )
        except DataError as exc:
            # The spec's `model:` line: where the inputs it names are given.
            raise exc.with_context(line=model.line) from None
    from ..data.fmu import run_fmu

    times = [c.time for c in reference.channels.values() if c.time.shape[0]]
    if not times:
        raise DataError("the reference has no samples to drive the FMU", file=str(spec.path))
    run = model.fmu_run
    start = max(float(t[0]) for t in times) if run.start_time is None else run.start_time
    stop = min(float(t[-1]) for t in times) if run.stop_time is None else run.stop_time
    return run_fmu(
        str(model.path),
        reference,
        dict(model.fmu_inputs),
        dict(model.fmu_outputs),
        start_time=start,
        stop_time=stop,
        step_size=model.step_size,
        parameters=dict(model.params),
        interface=run.interface,
        tolerance=run.tolerance,
    )


def check_model_columns(node: SignalSpec, model: Record) -> tuple[str, ...]:
    """The model columns a signal reads; one a model callable did not return is the spec
    line's error (the output is no file to point at)."""
    names = columns_of(node.sim, model)
    if model.meta.get("model_output"):
        for name in names:
            if name not in model.channels:
                error = model_column_error(model, name)
                raise DataError(
                    f"{model.source}: {error.problem}",
                    column=name,
                    line=node.line,
                    key=f"{node.key}.sim",
                    hint=error.hint,
                )
    return names
