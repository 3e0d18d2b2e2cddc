"""The environment the benchmarks run user commands in.

A benchmark times what a user waits for, so its child processes get the caller's environment
without the settings of a development shell that a user's terminal does not have: with
``PYTHONDONTWRITEBYTECODE`` Python recompiles every module on every run (and pytest redoes its
assertion rewrite of the plugin's modules), and ``PYTHONUNBUFFERED`` turns each character
pytest prints into a system call.
"""

from __future__ import annotations

import os
import resource
import subprocess
import time
from pathlib import Path

#: Development-shell settings a user's terminal does not have.
SHELL_ONLY = ("PYTHONDONTWRITEBYTECODE", "PYTHONUNBUFFERED")


def user_environment(**extra: str) -> dict[str, str]:
    """This process's environment without :data:`SHELL_ONLY`, plus ``extra``."""
    env = {key: value for key, value in os.environ.items() if key not in SHELL_ONLY}
    env.update(extra)
    return env


def timed_run(
    command: list[str], cwd: Path, env: dict[str, str] | None = None
) -> tuple[float, float, subprocess.CompletedProcess[str]]:
    """Run ``command`` as a user runs it (:func:`user_environment` unless ``env`` is given):
    its wall seconds, its CPU seconds (user + system of the child and everything it waited
    for), and the finished process, whose output the caller checks."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(
        command,
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
        env=user_environment() if env is None else env,
    )
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done
