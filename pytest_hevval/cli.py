"""``hevval``: the same pipeline as ``pytest --hevval``, without pytest.

    hevval run SPEC... [--json PATH] [--details] [--report html,json,md] [--report-dir DIR]
    hevval diagnose SPEC [--signal PATH] [--json PATH]
    hevval compare BEFORE AFTER [--format table|md|json] [--compare-fail EXPR]
    hevval history [--spec S] [--signal PATH] [--plot FILE]
    hevval --version

One argparse tree. An option that also exists as a pytest flag is spelled the same, without
the ``--hevval-`` prefix, and takes its help text and default from the same table
(:data:`pytest_hevval.options.OPTIONS`).

Exit codes: 0 every spec passed, 1 a gate failed, 2 bad input or usage.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from .defaults import SPEC_GLOBS
from .errors import HevvalError

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


def _write_json(path: str, payload: Any) -> None:
    from .files import write_atomic

    write_atomic(path, json.dumps(payload, indent=2, sort_keys=True, allow_nan=False) + "\n")


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


def _run(args: argparse.Namespace) -> int:
    from .engine import Evaluation
    from .run import RunOptions, run_specs
    from .spec.load import load_specs
    from .terminal import tree_summary

    specs = [spec for path in _expand(args.specs) for spec in load_specs(path)]
    if not specs:
        print("hevval run: no spec files found", file=sys.stderr)
        return EXIT_USAGE
    options = RunOptions(
        rootdir=Path.cwd(),
        figures="html" in (args.report or ""),
        workers=args.workers,
        dask=args.dask,
        data_hash=args.hash,
        intervals=not args.no_intervals,
    )
    progress = _progress(len(specs), enabled=not args.quiet and len(specs) > 1)
    done = [0]

    def advance(count: int) -> None:
        progress.update(count - done[0])
        done[0] = count

    outcomes = run_specs(specs, options, progress=advance)
    progress.close()
    results = []
    for outcome in outcomes:
        if not isinstance(outcome, Evaluation):
            raise outcome
        results.append(outcome.result)
    for line in tree_summary(results, details=args.details):
        print(line)
    from .campaign import campaign_verdicts, verdict_lines

    verdicts = campaign_verdicts(results)
    for found in verdicts:
        for line in verdict_lines(found):
            print(line)
    passed = all(r.passed for r in results) and all(v.passed for v in verdicts)
    from . import __version__

    payload = {
        "schema_version": 1,
        "hevval_version": __version__,
        "passed": passed,
        "specs": [r.to_dict() for r in results],
        **({"campaigns": [v.to_dict() for v in verdicts]} if verdicts else {}),
    }
    # The common single-spec case also exposes the spec's own fields at the top level.
    if len(results) == 1:
        payload.update(
            {k: v for k, v in results[0].to_dict().items() if k not in ("schema_version",)}
        )
    if args.json:
        _write_json(args.json, payload)
    if not args.no_history:
        _record_history(args, [r.to_dict() for r in results])
    if args.report:
        from .report import parse_formats, write_reports

        written = write_reports(
            [r.to_dict() for r in results],
            parse_formats(args.report),
            Path(args.report_dir),
            title="hevval validation report",
        )
        for path in written:
            print(f"report: {path}")
    return EXIT_OK if passed else EXIT_FAILED


def _record_history(args: argparse.Namespace, dicts: list[dict[str, Any]]) -> None:
    import os
    from datetime import datetime, timezone

    from .history import HistoryStore, make_record, resolve_model_version

    version = resolve_model_version(args.model_version, os.environ, Path.cwd())
    record = make_record(dicts, model_version=version, started_utc=datetime.now(timezone.utc))
    path = HistoryStore(Path(args.history_dir)).append(record)
    print(f"history: recorded {version} in {path}")


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
    return tqdm(total=total, unit="spec", file=sys.stderr)


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
    kwargs.update(overrides)
    parser.add_argument(f"--{name}", **kwargs)


def _workers(text: str) -> int:
    try:
        count = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number (got {text!r})") from None
    if count < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1 (got {count})")
    return count


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
    _shared(run, "no-history")
    _shared(run, "history-dir")
    _shared(run, "model-version")
    _shared(run, "dask", metavar="ADDRESS")
    _shared(run, "workers", type=_workers)
    _shared(run, "hash")
    _shared(run, "no-intervals")
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

    compare = commands.add_parser(
        "compare",
        help="compare two runs signal by signal",
        description="Compare two runs signal by signal: each λ, the physical errors and the "
        "lag, before → after, then Φ per spec.",
    )
    compare.add_argument(
        "before",
        help="run JSON, history record, history:latest, history:previous or history:<version>",
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


def _kernel(args: argparse.Namespace) -> int:
    from .core import kernel

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
        from .core.kernel import describe

        try:
            path = describe()
        except HevvalError as error:
            parser.exit(2, f"{self.version}\nhevval: {error}\n")
        print(f"{self.version}\n{path}")
        parser.exit()


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "run":
        return _run(args)
    if args.command == "diagnose":
        from .diagnose import run_diagnose

        return run_diagnose(args)
    if args.command == "kernel":
        return _kernel(args)
    from .history.cli import run_compare, run_history

    return run_compare(args) if args.command == "compare" else run_history(args)


def main(argv: Sequence[str] | None = None) -> int:
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
        return _dispatch(args)
    except HevvalError as exc:
        print(f"hevval {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
