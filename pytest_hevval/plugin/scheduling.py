"""How the plugin hands spec items to xdist workers (``--dist load``, the default).

xdist's ``LoadScopeScheduling`` keeps every item of one scope on one worker: a spec file's
items, or one recording's items of a campaign (the scope of a node id is all but its last
``::`` part), so each data file is read once. Two things in it do not suit spec items:

- it sends a worker more work only when two items or fewer are left in its queue, and a
  worker runs an item only once it knows the next one. A spec's items are judged by the last
  of them (``items.carry_spec_items``), so the others finish at once and the worker then waits
  a round trip to the controller, with the whole spec still to score, for every spec;
- it counts a worker's pending items over all work it was ever given on every report, so a
  campaign of thousands of items costs the controller time quadratic in its size.

This scheduler keeps :data:`QUEUED_SCOPES` scopes on each worker while many are left, two
near the end of the queue, and forgets a scope once all its items are done.
"""

from __future__ import annotations

from typing import Any

from xdist.scheduler import LoadScopeScheduling

#: Scopes (specs, or a campaign's recordings) each worker holds at once while many are left:
#: the one it runs and the next two, so that it has the next scope's first item before the
#: controller has reported the last one (under -n 2 on a 200-recording campaign a worker
#: waited 1.4 s for work with two, 0.13 s with three).
QUEUED_SCOPES = 3


class SpecScheduling(LoadScopeScheduling):  # type: ignore[misc]  # xdist ships no types
    """``LoadScopeScheduling`` that keeps each worker's queue :data:`QUEUED_SCOPES` scopes
    deep (two near the end) and tracks only unfinished scopes."""

    def __init__(self, config: Any, log: Any = None) -> None:
        super().__init__(config, log)
        self._positions: dict[Any, dict[str, int]] = {}

    def mark_test_complete(self, node: Any, item_index: int, duration: float = 0) -> None:
        nodeid = self.registered_collections[node][item_index]
        scope = self._split_scope(nodeid)
        work = self.assigned_work[node]
        unit = work[scope]
        unit[nodeid] = True
        if all(unit.values()):
            del work[scope]
        self._reschedule(node)

    def _reschedule(self, node: Any) -> None:
        if node.shutting_down:
            return
        if not self.workqueue:
            node.shutdown()
            return
        while self.workqueue and len(self.assigned_work[node]) < self._depth():
            self._assign_work_unit(node)

    def _depth(self) -> int:
        # Near the end of the queue, two scopes per worker: the last scopes go to whichever
        # worker frees up first, so the workers end together.
        plenty = len(self.workqueue) >= QUEUED_SCOPES * len(self.assigned_work)
        return QUEUED_SCOPES if plenty else 2

    def _assign_work_unit(self, node: Any) -> None:
        scope, work_unit = self.workqueue.popitem(last=False)
        self.assigned_work.setdefault(node, {})[scope] = work_unit
        positions = self._positions.get(node)
        if positions is None:
            collection = self.registered_collections[node]
            positions = self._positions[node] = {nodeid: i for i, nodeid in enumerate(collection)}
        node.send_runtest_some(
            [positions[nodeid] for nodeid, completed in work_unit.items() if not completed]
        )
