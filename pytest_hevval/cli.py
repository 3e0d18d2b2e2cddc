"""``hevval``: the same pipeline as ``pytest --hevval``, without pytest.

    hevval run SPEC... [--json PATH] [--details] [--report html,json,md] [--report-dir DIR]
               [--compare [VERSION]] [--compare-fail EXPR] [--ratchet [MARGIN]]
    hevval diagnose SPEC [--signal PATH] [--json PATH]
    hevval compare BEFORE AFTER [--format table|md|json] [--compare-fail EXPR]
    hevval history [--spec S] [--signal PATH] [--plot FILE]
    hevval trace [RUN] [--requirements FILE] [--format table|md|csv|html|json]
    hevval evidence [RUN] [--output PATH]
    hevval --version

One argparse tree. An option that also exists as a pytest flag is spelled the same, without
the ``--hevval-`` prefix, and takes its help text and default from the same table
(:data:`pytest_hevval.options.OPTIONS`).

Exit codes: 0 every spec passed, 1 a gate failed, 2 bad input or usage.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from .defaults import SPEC_GLOBS
from .errors import HevvalError

if TYPE_CHECKING:
    from .history import Comparison, HistoryRow

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
#: The exit code of each outcome of a run (``results.verdict.Outcome``, by value).
_EXIT_CODES = {"passed": EXIT_OK, "failed": EXIT_FAILED, "error": EXIT_USAGE}


def _write_json(path: str, payload: Any) -> None:
    from .files import write_atomic
    from .results.codec import dumps

    write_atomic(path, dumps(payload))


def _expand(paths: Sequence[str]) -> list[Path]:
    found: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            for pattern in SPEC_GLOBS:
                found.extend(sorted(path.rglob(pattern)))
        else:
            found.append(path)
    return found


# -- hevval run -------------------------------------------------------------------------------


def _run(args: argparse.Namespace) -> int:
    """``hevval run``: the command line's options into one run, and what it says printed."""
    from .flags import COMMAND
    from .run import Run, RunSettings
    from .spec.load import load_specs

    rootdir = project_root(args.specs)
    run = Run(RunSettings.read(lambda name: _arg(args, name), rootdir, COMMAND))
    specs = [spec for path in _expand(args.specs) for spec in load_specs(path)]
    if not specs:
        print("hevval run: no spec files found", file=sys.stderr)
        return EXIT_USAGE
    run.start()
    progress = _progress(len(specs), enabled=not args.quiet and len(specs) > 1)
    done = [0]

    def advance(count: int) -> None:
        progress.update(count - done[0])
        done[0] = count

    run.score(specs, progress=advance)
    progress.close()
    run.close_scoring()
    verdict = run.finish()
    for line in run.summary():
        print(line)
    if args.json:
        _write_json(args.json, run.json_document())
    for line in run.annotations:
        _own_line(line)
    for note in run.notes:
        print(note)
    for item in verdict.regressions:
        accepted = " (accepted)" if verdict.regressions_accepted else ""
        print(f"regression{accepted}: {item.text}")
    # The others were scored and published; the specs that could not be are named once each.
    for _, error in run.errors:
        print(f"hevval run: error: {error}", file=sys.stderr)
    return _EXIT_CODES[verdict.outcome.value]


#: Files that make a folder pytest's rootdir, with the section that must be in them (if any).
_PYTEST_CONFIGS = (
    ("pytest.ini", None),
    (".pytest.ini", None),
    ("pyproject.toml", b"[tool.pytest.ini_options]"),
    ("tox.ini", b"[pytest]"),
    ("setup.cfg", b"[tool:pytest]"),
)


def project_root(targets: Sequence[str]) -> Path:
    """The folder ``pytest --hevval`` would take as its rootdir for these spec paths: the
    nearest folder holding a pytest configuration, from the targets' common folder upwards;
    else the current folder. Model modules are imported from it, and results name files
    relative to it, as under pytest."""
    from .defaults import split_key
    from .files import read_input

    folders = []
    for target in targets or ["."]:
        path = Path(split_key(str(target))[0]).resolve()
        folders.append(str(path if path.is_dir() else path.parent))
    common = Path(os.path.commonpath(folders))
    for folder in (common, *common.parents):
        for name, section in _PYTEST_CONFIGS:
            try:
                text = read_input(folder / name)
            except (OSError, ValueError):
                continue
            if section is None or section in text:
                return folder
    return Path.cwd()


def _arg(args: argparse.Namespace, name: str) -> Any:
    """The value of ``--NAME`` (an option of the shared table) as parsed."""
    return getattr(args, name.replace("-", "_"), None)


# -- hevval diagnose --------------------------------------------------------------------------


def _diagnose(args: argparse.Namespace) -> int:
    """``hevval diagnose``: trace the residual of a signal to the effect the model lacks."""
    from .errors import SpecError
    from .report.diagnosis_text import describe, payload, tried_lines, tried_payload
    from .scoring.candidates import candidates_for
    from .scoring.diagnosis import diagnose_signal
    from .scoring.fixes import try_term
    from .scoring.run import RunOptions, run_specs
    from .spec.load import load_specs

    if args.try_term is not None and len(args.signal or []) != 1:
        raise SpecError(
            "--try adds a term to one signal's simulated output",
            file=args.spec,
            hint="name the signal: hevval diagnose SPEC --signal E_batt/P_batt --try '…'",
        )

    specs = load_specs(args.spec)
    if len(specs) > 1:
        raise SpecError(
            f"the spec is a campaign of {len(specs)} recordings; diagnose one at a time",
            file=args.spec,
            hint=f"name one: hevval diagnose '{args.spec}::{specs[0].recording}'",
        )
    (spec,) = specs
    (outcome,) = run_specs([spec], RunOptions(rootdir=project_root([args.spec]), keep_arrays=True))
    if isinstance(outcome, HevvalError):
        raise outcome
    evaluation = outcome
    paths = args.signal or [s.path for s in evaluation.result.signals if s.origin]
    if not paths:
        print(f"{spec.name}: every signal passes; pass --signal PATH to diagnose one anyway")
    candidates = candidates_for(evaluation, channels=not args.no_channels) if paths else []
    findings = [payload(diagnose_signal(evaluation, p, candidates=candidates)) for p in paths]
    for found in findings:
        for line in describe(found):
            print(line)
    tried = None if args.try_term is None else try_term(evaluation, paths[0], args.try_term)
    if tried is not None:
        for line in tried_lines(tried):
            print(line)
    if args.json:
        document: dict[str, Any] = {"spec": spec.name, "signals": findings}
        if tried is not None:
            document["tried"] = tried_payload(tried)
        if len(findings) == 1:
            # One signal: its fields also sit at the top level, as documented.
            document.update(findings[0])
        _write_json(args.json, document)
    return EXIT_OK


# -- hevval history and hevval compare --------------------------------------------------------


def _write(text: str, output: str | None) -> None:
    from .errors import OutputError
    from .files import write_atomic
    from .history import HistoryError

    if output is None or output == "-":
        sys.stdout.write(text)
        return
    try:
        write_atomic(output, text)
    except OutputError:
        raise
    except OSError as exc:
        raise HistoryError(
            f"cannot write: {exc.strerror or exc}", file=output, hint="choose another --output"
        ) from None


def _history(args: argparse.Namespace) -> int:
    """``hevval history``: Φ and the characteristics over the recorded model versions."""
    from .history import (
        HistoryStore,
        history_table,
        plot_history,
        render_history_table,
        report_problems,
    )

    store = HistoryStore(Path(args.history_dir))
    runs = store.runs()
    report_problems(store)
    rows = history_table(runs, spec=args.spec, signal=args.signal)
    if not rows:
        what = "no readable records" if not runs else "no recorded runs match"
        print(f"hevval history: {what} in {args.history_dir}", file=sys.stderr)
        return 1
    if args.json is not None:
        document = {"rows": [row.to_dict() for row in rows]}
        _write(json.dumps(document, indent=2, ensure_ascii=False) + "\n", args.json)
    if args.json != "-":
        sys.stdout.write(render_history_table(rows) + "\n")
        steps = _step_report(rows, args.min_step)
        if steps:
            sys.stdout.write("\n" + "\n".join(steps) + "\n")
    if args.plot is not None:
        plot_history(rows, Path(args.plot))
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


def _step_report(rows: Sequence[HistoryRow], min_size: float) -> list[str]:
    from .history import detect_steps
    from .history.trends import characteristic_names, row_series

    lines = []
    for (spec, signal), series in row_series(rows).items():
        fields = ["phi"] if signal is None else ["phi", *characteristic_names(series)]
        for field in fields:
            steps = detect_steps(
                [r.value(field) for r in series],
                min_size=min_size,
                intervals=[r.interval(field) for r in series],
            )
            for step in steps:
                if not step.regression:
                    continue
                at = series[step.index]
                label = "Φ" if field == "phi" else field
                where = spec if signal is None else f"{spec}::{signal}"
                lines.append(
                    f"drop: {where} {label} {step.before:.4f} → {step.after:.4f} "
                    f"from model version {at.model_version} ({at.started_utc[:10]})"
                )
    return sorted(set(lines))


def _compare(args: argparse.Namespace) -> int:
    """``hevval compare``: two runs signal by signal, then Φ per spec."""
    from .flags import COMMAND
    from .history import compare, load_side, parse_compare_fail, regressions
    from .history.compare import campaign_change_lines
    from .history.render import render
    from .history.runtime_changes import runtime_change_lines, runtime_changes
    from .results.codec import plain_json

    rules = (
        parse_compare_fail(args.compare_fail, front_end=COMMAND)
        if args.compare_fail is not None
        else None
    )
    directory = Path(args.history_dir)
    before, before_label = load_side(args.before, directory)
    after, after_label = load_side(args.after, directory)
    if before_label == after_label:
        before_label, after_label = f"{before_label} (before)", f"{after_label} (after)"
    # Two runs named on the command line are meant to be compared, so one spec against one
    # spec pairs even when the model version lives in the file name (trip-v1 → trip-v2).
    comparison = compare(
        after, before, before_label=before_label, after_label=after_label, pair_single=True
    )
    found = regressions(comparison, rules) if rules is not None else None
    text = _with_pairings(render(comparison, args.format, found), comparison, args.format)
    slower = runtime_changes(before, after)
    if args.format != "json":
        text += "".join(f"\n{line}\n" for line in campaign_change_lines(comparison))
        text += "".join(
            f"\n{line}\n" for line in runtime_change_lines(slower, before_label, after_label)
        )
    elif slower:
        document = json.loads(text)
        document["runtime"] = plain_json([change.to_dict() for change in slower])
        text = json.dumps(document, indent=2, ensure_ascii=False, allow_nan=False) + "\n"
    _write(text, args.output)
    # A runtime regression fails the comparison as any other when regressions are to fail it.
    slowed = rules is not None and any(change.regression for change in slower)
    return 1 if found or slowed else 0


def _trace(args: argparse.Namespace) -> int:
    """``hevval trace``: each requirement → the items that verify it → their latest verdict."""
    from .history import latest_results, load_document
    from .history.load import side_label
    from .report.trace import read_requirement_list, render_trace, trace_rows
    from .results.spec_result import SpecResult

    listed = read_requirement_list(args.requirements) if args.requirements else None
    if args.run is None:
        # Each spec's newest recorded verdict, whichever run recorded it.
        latest = latest_results(Path(args.history_dir))
        versions = {str(s["spec"]): str(s["model_version"]) for s in latest}
        typed = [SpecResult.from_dict(s) for s in latest]
        rows = trace_rows(typed, versions=versions, listed=listed)
    else:
        found = load_document(args.run, Path(args.history_dir))
        rows = trace_rows(
            [SpecResult.from_dict(s) for s in found.specs],
            model_version=side_label(found, args.run),
            listed=listed,
        )
    if not rows:
        print(
            f"hevval trace: no spec of {args.run} names requirements "
            "(give specs `requirements: [ID, ...]`, see docs/spec.md)",
            file=sys.stderr,
        )
        return EXIT_FAILED
    _write(render_trace(rows, args.format), args.output)
    failed = any(row.passed is not True for row in rows)
    return EXIT_FAILED if failed else EXIT_OK


def _evidence(args: argparse.Namespace) -> int:
    """``hevval evidence``: the evidence record of a run, from its JSON or its history record."""
    from .history import load_document
    from .report.evidence import render_evidence
    from .results.spec_result import SpecResult

    found = load_document(args.run or "history:latest", Path(args.history_dir))
    specs = [SpecResult.from_dict(s) for s in found.specs]
    text = render_evidence(specs, found.facts, source=found.source)
    _write(text, args.output)
    return EXIT_OK


def _with_pairings(text: str, comparison: Comparison, fmt: str) -> str:
    """Say under the title which different specs were compared and whose data changed; JSON
    carries ``pairings`` and each spec's ``data_changed``."""
    from .escape import markdown

    if fmt == "json" or not comparison.notes:
        return text
    title, _, rest = text.partition("\n")
    if fmt == "md":
        # A blank line ends the heading; two trailing spaces break lines inside the paragraph.
        notes = [markdown(note) for note in comparison.notes]
        return title + "\n\n" + "  \n".join(notes) + "\n" + rest
    return title + "\n" + "".join(note + "\n" for note in comparison.notes) + rest


class _NoProgress:
    def update(self, n: int) -> None:
        return None

    def close(self) -> None:
        return None


def _progress(total: int, *, enabled: bool) -> Any:
    if not enabled or not sys.stderr.isatty():
        return _NoProgress()
    try:
        from tqdm import tqdm
    except ImportError:
        return _NoProgress()
    # The bar redraws itself with a carriage return, which the terminal rule would show.
    return tqdm(total=total, unit="spec", file=getattr(sys.stderr, "raw", sys.stderr))


class _UsageError(HevvalError):
    """A command line argparse could not make sense of; worded like every other error."""

    def __init__(self, prog: str, message: str) -> None:
        super().__init__(message, hint=f"see `{prog} --help`")
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """Usage errors become exceptions, so every error leaves by one path with one wording."""

    def error(self, message: str) -> NoReturn:
        raise _UsageError(self.prog, message)


def _shared(parser: argparse.ArgumentParser, name: str, **overrides: Any) -> None:
    """Add the option that pytest spells ``--hevval-NAME``, as ``--NAME``, from its table."""
    from .options import option_named

    option = option_named(name)
    kwargs: dict[str, Any] = {"help": option.help}
    if option.kind == "bool":
        kwargs["action"] = "store_true"
    else:
        kwargs["default"] = option.default
    if option.choices:
        kwargs["choices"] = option.choices
    if option.const is not None:
        kwargs["nargs"] = "?"
        kwargs["const"] = option.const
    kwargs.update(overrides)
    parser.add_argument(f"--{name}", **kwargs)


def _workers(text: str) -> int:
    """``--workers``, checked by the run's own rule (:func:`pytest_hevval.run.worker_count`)."""
    from .run.settings import worker_count

    try:
        return worker_count(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = _Parser(
        prog="hevval",
        description="Multi-fidelity validation of simulation models against measured data.",
        epilog="Each command has its own --help. The same checks run as tests: pytest --hevval.",
    )
    parser.add_argument(
        "--version", action=_VersionAction, version=_version_text(__version__), nargs=0
    )
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )

    run = commands.add_parser("run", help="score specs and print the signal trees")
    run.add_argument("specs", nargs="+", help="spec files or folders holding *.hevval.yaml")
    run.add_argument("--json", metavar="PATH", help="write the results as JSON to this path")
    _shared(run, "details")
    _shared(run, "report")
    _shared(run, "report-dir")
    _shared(run, "history")
    _shared(run, "no-history")
    _shared(run, "history-dir")
    _shared(run, "model-version")
    _shared(run, "dask", metavar="ADDRESS")
    _shared(run, "workers", type=_workers)
    _shared(run, "hash")
    _shared(run, "no-intervals")
    _shared(run, "diagnose")
    _shared(run, "compare", metavar="VERSION")
    _shared(run, "compare-fail", metavar="EXPR")
    _shared(run, "create-baseline")
    _shared(run, "accept")
    _shared(run, "ratchet", metavar="MARGIN")
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    diagnose = commands.add_parser(
        "diagnose", help="trace the residual of a signal to the effect the model lacks"
    )
    diagnose.add_argument("spec", help="a *.hevval.yaml spec")
    diagnose.add_argument(
        "--signal",
        action="append",
        help="signal path (repeatable); default: every signal where an error appears",
    )
    diagnose.add_argument("--json", metavar="PATH", help="write the findings as JSON to this path")
    diagnose.add_argument(
        "--no-channels",
        action="store_true",
        help="only the spec's declared candidates, not every unused measured channel",
    )
    diagnose.add_argument(
        "--try",
        dest="try_term",
        metavar="TERM",
        help="score the signal again with TERM (over the reference's columns and the spec's "
        "candidates, e.g. '1.2 * heating_kw - 2.9') added to the model's output",
    )

    compare = commands.add_parser(
        "compare",
        help="compare two runs signal by signal",
        description="Compare two runs signal by signal: each λ, the physical errors and the "
        "lag, before → after, then Φ per spec.",
    )
    compare.add_argument(
        "before",
        help="run JSON, history record, history:latest, history:previous, history:accepted "
        "or history:<version>",
    )
    compare.add_argument("after", help="same forms as BEFORE")
    _shared(compare, "history-dir")
    compare.add_argument("--format", choices=("table", "md", "json"), default="table")
    compare.add_argument("--output", metavar="PATH", help="write here instead of stdout")
    _shared(
        compare,
        "compare-fail",
        metavar="EXPR",
        help="exit 1 on regressions, e.g. phi:0.01,lambda:0.02 or mae:1%% (see docs/history.md)",
    )

    history = commands.add_parser(
        "history",
        help="Φ and λ over the recorded model versions, with lasting drops",
        description="Show Φ (and the characteristics of a signal) over the recorded model "
        "versions, and flag lasting drops.",
    )
    _shared(history, "history-dir")
    history.add_argument("--spec", help="spec path or name (shell glob allowed)")
    history.add_argument("--signal", help="signal path or name (shell glob allowed)")
    history.add_argument("--plot", metavar="FILE", help="write a PNG or SVG plot")
    history.add_argument("--json", metavar="PATH", help="write the rows as JSON ('-' = stdout)")
    history.add_argument(
        "--min-step",
        type=float,
        default=0.01,
        help="smallest change of Φ or λ reported as a step (default 0.01)",
    )
    trace = commands.add_parser(
        "trace",
        help="requirements → the specs and signals that verify them → their latest verdict",
        description="Each requirement the specs name, the specs and signals that verify it, "
        "and their latest verdict with Φ and its interval, the model version and the data. "
        "With --requirements, listed requirements that nothing verifies show as uncovered.",
    )
    _recorded_run(trace, "default: each spec's newest recorded result")
    trace.add_argument(
        "--requirements",
        metavar="FILE",
        help="the team's requirement IDs: one a line, or a CSV file whose first column holds them",
    )
    trace.add_argument("--format", choices=("table", "md", "csv", "html", "json"), default="table")
    trace.add_argument("--output", metavar="PATH", help="write here instead of stdout")
    evidence = commands.add_parser(
        "evidence",
        help="the evidence record of a run (JSON, with a published schema)",
        description="Write the evidence record of a run: tool and environment, the spec and "
        "data files' digests, the model's identity and parameters, every verdict with its "
        "interval, the requirement links and the model's runtime (docs/evidence.md).",
    )
    _recorded_run(evidence, "default history:latest, the newest record")
    evidence.add_argument("--output", metavar="PATH", help="write here instead of stdout")
    kernel = commands.add_parser(
        "kernel",
        help="show which path scores records; --compile fills the compiled kernel's cache",
        description="Show which path scores records (numpy, or the compiled kernel of the fast "
        "extra) and whether numba's cache holds the kernel. Short records take the kernel only "
        "once it is cached; --compile caches it now.",
    )
    kernel.add_argument(
        "--compile",
        action="store_true",
        help="compile every function of the kernel into numba's cache (seconds, once per "
        "environment; NUMBA_CACHE_DIR chooses the folder)",
    )
    return parser


def _recorded_run(command: argparse.ArgumentParser, default_help: str) -> None:
    """The RUN operand of ``trace`` and ``evidence``, and the history folder it is looked up in."""
    command.add_argument(
        "run",
        nargs="?",
        help=f"{default_help}; history:<version>, a history record or a `hevval run --json` file",
    )
    _shared(command, "history-dir")


def _kernel(args: argparse.Namespace) -> int:
    from .data import kernel_cache as kernel

    if args.compile:
        for name, seconds in kernel.compile_all().items():
            print(f"compiled {name:<16} {seconds:6.2f} s")
    print(kernel.describe())
    if kernel.active_path() == "numba":
        cached = kernel.cached_functions()
        missing = [name for name, found in cached.items() if not found]
        state = f"missing {', '.join(missing)}" if missing else "every function"
        print(f"cache: {kernel.cache_folder()} ({state})")
    return EXIT_OK


def _version_text(version: str) -> str:
    return f"pytest-hevval {version}"


class _VersionAction(argparse.Action):
    """Prints the version and the active scoring path (this loads numba, so only on request)."""

    def __init__(self, option_strings: list[str], version: str, **kwargs: Any) -> None:
        super().__init__(
            option_strings, help="show the version and the scoring path, then exit", **kwargs
        )
        self.version = version

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        from .data.kernel_cache import describe

        try:
            path = describe()
        except HevvalError as error:
            parser.exit(2, f"{self.version}\nhevval: {error}\n")
        print(f"{self.version}\n{path}")
        parser.exit()


_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "run": _run,
    "diagnose": _diagnose,
    "compare": _compare,
    "history": _history,
    "trace": _trace,
    "evidence": _evidence,
    "kernel": _kernel,
}


def _dispatch(args: argparse.Namespace) -> int:
    return _COMMANDS[args.command](args)


def _own_line(line: str) -> None:
    """Print one of the project's own workflow commands, which the terminal rule would
    neutralise (see :mod:`pytest_hevval.escape`)."""
    from .escape import TerminalStream

    if isinstance(sys.stdout, TerminalStream):
        sys.stdout.writeraw(line + "\n")
    else:
        print(line)


def main(argv: Sequence[str] | None = None) -> int:
    """Every line hevval prints goes through the terminal rule of :mod:`pytest_hevval.escape`:
    text from specs, data files and history records cannot forge a workflow command or send
    escape sequences, and a console that cannot encode ``Φ`` gets an escape, not an error."""
    from .escape import TerminalStream
    from .files import remove_temporaries_on_signals

    remove_temporaries_on_signals()
    stdout, stderr = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = TerminalStream(stdout), TerminalStream(stderr)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = stdout, stderr


def _main(argv: Sequence[str] | None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    try:
        args, unknown = _parser().parse_known_args(arguments)
        if unknown:
            # Named after the subcommand, whose --help lists what it takes.
            raise _UsageError(
                f"hevval {args.command}", f"unrecognized arguments: {' '.join(unknown)}"
            )
    except _UsageError as exc:
        print(f"{exc.prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help and --version print and exit
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    try:
        from .core.registry import load_entry_points

        load_entry_points()
        code = _dispatch(args)
        # What is still buffered is written here, so that a reader that went away while it
        # waited is handled below as one that left mid-run (at the interpreter's exit, the
        # failed write would print an ignored BrokenPipeError and exit with 120).
        sys.stdout.flush()
        return code
    except HevvalError as exc:
        print(f"hevval {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader went away (`hevval run … | head`): nothing more can be shown. Point
        # stdout at the null device so that flushing it at exit cannot fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILED


if __name__ == "__main__":
    raise SystemExit(main())
