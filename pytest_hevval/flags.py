"""How each front end spells an option, so a message names the flag the user typed.

pytest spells the option NAME ``--hevval-NAME``; ``hevval run`` spells it ``--NAME`` (both take
their names, help and defaults from options.py). Code below the front ends that words a
message about an option takes a :class:`FrontEnd` and asks it for the flag.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["COMMAND", "PYTEST", "FrontEnd"]


@dataclass(frozen=True)
class FrontEnd:
    #: What the user ran, as a message names it: ``pytest`` or ``hevval run``.
    name: str
    #: What comes before an option's name on this front end's command line.
    prefix: str

    def flag(self, option: str) -> str:
        """``--hevval-report`` under pytest, ``--report`` for ``hevval run``."""
        return f"{self.prefix}{option}"


PYTEST = FrontEnd("pytest", "--hevval-")
COMMAND = FrontEnd("hevval run", "--")
