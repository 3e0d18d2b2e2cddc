"""The environment the benchmarks run user commands in.

A benchmark times what a user waits for, so its child processes get the caller's environment
without the settings of a development shell that a user's terminal does not have: with
``PYTHONDONTWRITEBYTECODE`` Python recompiles every module on every run (and pytest redoes its
assertion rewrite of the plugin's modules), and ``PYTHONUNBUFFERED`` turns each character
pytest prints into a system call.
"""

from __future__ import annotations

import os

#: Development-shell settings a user's terminal does not have.
SHELL_ONLY = ("PYTHONDONTWRITEBYTECODE", "PYTHONUNBUFFERED")


def user_environment(**extra: str) -> dict[str, str]:
    """This process's environment without :data:`SHELL_ONLY`, plus ``extra``."""
    env = {key: value for key, value in os.environ.items() if key not in SHELL_ONLY}
    env.update(extra)
    return env
