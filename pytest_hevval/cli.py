"""``hevval``: the same engine without pytest.

    hevval run SPEC... [--json PATH] [--details] [--report html,json,md] [--report-dir DIR]
    hevval diagnose SPEC [--signal PATH] [--json PATH]
    hevval compare BEFORE AFTER [--format table|md|json]
    hevval history [--spec S] [--signal PATH] [--plot FILE]

Exit codes: 0 every spec passed, 1 a gate failed, 2 bad input or usage.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .data.remote import is_url
from .errors import HevvalError

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


def _write_json(path: str, payload: Any) -> None:
    """Write atomically: a reader never sees half a file, a failure leaves the old one."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        temporary.write_text(json.dumps(payload, indent=2, sort_keys=True, allow_nan=False) + "\n")
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)


def _expand(paths: Sequence[str]) -> list[Path]:
    found: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found.extend(sorted(path.rglob("*.hevval.yaml")))
            found.extend(sorted(path.rglob("*.hevval.yml")))
        else:
            found.append(path)
    return found


def _run(args: argparse.Namespace) -> int:
    from .engine import DataCache, evaluate_spec
    from .spec.load import load_spec
    from .terminal import tree_summary

    specs = [load_spec(p) for p in _expand(args.specs)]
    if not specs:
        print("hevval run: no spec files found", file=sys.stderr)
        return EXIT_USAGE
    cache = DataCache()
    for spec in specs:
        cache.declare(spec.reference, spec.reference_columns())
        cache.declare(spec.model, spec.model_columns())
    wants_figures = "html" in (args.report or "")
    results = []
    progress = _progress(len(specs), enabled=not args.quiet and len(specs) > 1)
    if args.dask:
        from .distributed import error_from_payload, evaluate_on_dask, is_error_payload
        from .result import SpecResult

        done = [0]

        def advance(count: int) -> None:
            progress.update(count - done[0])
            done[0] = count

        payloads = evaluate_on_dask(
            [s.path for s in specs],
            args.dask,
            rootdir=Path.cwd(),
            figures=wants_figures,
            progress=advance,
        )
        for payload in payloads:
            if is_error_payload(payload):
                raise error_from_payload(payload)
            results.append(SpecResult.from_dict(payload))
    else:
        for spec in specs:
            evaluation = evaluate_spec(spec, cache=cache, rootdir=Path.cwd(), figures=wants_figures)
            results.append(evaluation.result)
            progress.update(1)
    progress.close()
    for result in results:
        if not is_url(result.spec):
            result.spec = os.path.relpath(result.spec)
    for line in tree_summary(results, details=args.details):
        print(line)
    passed = all(r.passed for r in results)
    payload = {
        "schema_version": 1,
        "passed": passed,
        "specs": [r.to_dict() for r in results],
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hevval",
        description="Multi-fidelity validation of simulation models against measured data.",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="score specs and print the signal trees")
    run.add_argument("specs", nargs="+", help="spec files or folders holding *.hevval.yaml")
    run.add_argument("--json", help="write the results as JSON to this path")
    run.add_argument("--details", action="store_true", help="show every node")
    run.add_argument("--report", default="", help="write reports: html,json,md")
    run.add_argument("--report-dir", default=".hevval/report", help="folder for reports")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--no-history", action="store_true", help="do not record this run")
    run.add_argument("--history-dir", default=".hevval/history", help="folder of run records")
    run.add_argument("--model-version", help="model version recorded in the history")
    run.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="evaluate specs on this dask.distributed scheduler ('local' starts one here)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    from .core.registry import load_entry_points

    try:
        load_entry_points()
    except HevvalError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    # Subcommands implemented in their own modules parse their own arguments.
    delegated = {
        "compare": ("pytest_hevval.history", "compare_main"),
        "history": ("pytest_hevval.history", "history_main"),
        "diagnose": ("pytest_hevval.diagnose", "diagnose_main"),
    }
    try:
        if arguments and arguments[0] in delegated:
            import importlib

            module_name, function = delegated[arguments[0]]
            handler = getattr(importlib.import_module(module_name), function)
            return int(handler(arguments[1:]))
        args = _parser().parse_args(arguments)
        if args.command == "run":
            return _run(args)
    except HevvalError as exc:
        print(f"hevval: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    return EXIT_USAGE


if __name__ == "__main__":
    raise SystemExit(main())
