"""``hevval`` commands run in the example project's folder, all in one fresh process: the
example's model packages (`models`, `bus`) are then imported away from the test session, and
the package is imported once for every command."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parent.parent / "example_project"

_DRIVER = """
import json, sys
from pytest_hevval.cli import main
commands, codes = json.loads(sys.argv[1]), {}
for name, argv in commands.items():
    print(f"=== {name}", flush=True)
    codes[name] = main(argv)
print("=== codes")
print(json.dumps(codes))
"""


def run_in_example(commands: dict[str, list[str]]) -> tuple[dict[str, int], dict[str, str]]:
    """Run each command's argv (``["diagnose", SPEC, ...]``) in turn; their exit codes and
    printed output, by name."""
    done = subprocess.run(
        [sys.executable, "-c", _DRIVER, json.dumps(commands)],
        cwd=EXAMPLE,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    parts = (part.split("\n", 1) for part in done.stdout.split("=== ")[1:])
    printed = {name: text for name, text in parts}
    codes: dict[str, int] = json.loads(printed.pop("codes"))
    return codes, printed
