"""The run: one object that both front ends drive, from options to verdict to published files.

``settings.py`` reads a front end's options once into :class:`RunSettings`; ``pipeline.py``'s
:class:`Run` starts the run, scores its specs, decides its one verdict, publishes and
finishes. ``hevval run`` (:mod:`pytest_hevval.cli`) and ``pytest --hevval``
(:mod:`pytest_hevval.plugin`) only translate their flags and print what the run says.
"""

from __future__ import annotations

from .pipeline import ClusterUnavailable, Run
from .settings import RunSettings, worker_count

__all__ = ["ClusterUnavailable", "Run", "RunSettings", "worker_count"]
