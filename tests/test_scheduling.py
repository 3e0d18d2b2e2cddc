"""The plugin's xdist scheduler (``plugin.scheduling.SpecScheduling``), driven as xdist's
controller drives it: collections in, items out to fake workers, completions back."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from pytest_hevval.plugin.scheduling import QUEUED_SCOPES, SpecScheduling


class FakeWorker:
    """What the scheduler calls on a worker: the items it is sent, and its shutdown."""

    def __init__(self, name: str) -> None:
        self.gateway = SimpleNamespace(id=name)
        self.sent: list[int] = []
        self.shutting_down = False

    def send_runtest_some(self, indices: list[int]) -> None:
        self.sent.extend(indices)

    def shutdown(self) -> None:
        self.shutting_down = True


def _config(workers: int) -> Any:
    option = SimpleNamespace(loadscopereorder=False)
    return SimpleNamespace(getvalue=lambda name: [f"{workers}*popen"], option=option)


def _campaign(recordings: int, items: int) -> list[str]:
    return [
        f"fleet.hevval.yaml::rec{r:03d}::signal{i}" for r in range(recordings) for i in range(items)
    ]


def _start(collection: list[str], workers: int) -> tuple[SpecScheduling, list[FakeWorker]]:
    scheduler = SpecScheduling(_config(workers))
    nodes = [FakeWorker(f"gw{i}") for i in range(workers)]
    for node in nodes:
        scheduler.add_node(node)
        scheduler.add_node_collection(node, collection)
    scheduler.schedule()
    return scheduler, nodes


def _recordings(collection: list[str], node: FakeWorker) -> list[str]:
    seen: list[str] = []
    for index in node.sent:
        recording = collection[index].split("::")[1]
        if recording not in seen:
            seen.append(recording)
    return seen


def test_each_worker_holds_whole_recordings_and_the_next_one_before_it_runs_out() -> None:
    collection = _campaign(recordings=20, items=4)
    scheduler, (first, second) = _start(collection, workers=2)
    # Each worker holds its queue's depth of whole recordings, none shared.
    assert len(_recordings(collection, first)) == QUEUED_SCOPES
    assert len(_recordings(collection, second)) == QUEUED_SCOPES
    assert not set(_recordings(collection, first)) & set(_recordings(collection, second))
    assert len(first.sent) == QUEUED_SCOPES * 4
    # The worker finishes its first recording: the next arrives at once, so it always knows
    # the item after the one it runs, whichever item of a recording judges the others.
    for index in first.sent[:4]:
        scheduler.mark_test_complete(first, index)
    assert len(_recordings(collection, first)) == QUEUED_SCOPES + 1
    # Three of four items done is not a finished recording: nothing more is sent.
    for index in first.sent[4:7]:
        scheduler.mark_test_complete(first, index)
    assert len(_recordings(collection, first)) == QUEUED_SCOPES + 1


def test_every_item_runs_once_and_the_workers_shut_down_when_the_queue_is_empty() -> None:
    collection = _campaign(recordings=25, items=3)
    scheduler, nodes = _start(collection, workers=2)
    done = [0, 0]
    # Let the workers complete what they hold, in turn, until nothing is left.
    while not all(node.shutting_down for node in nodes) or any(
        done[i] < len(node.sent) for i, node in enumerate(nodes)
    ):
        for i, node in enumerate(nodes):
            if done[i] < len(node.sent):
                scheduler.mark_test_complete(node, node.sent[done[i]])
                done[i] += 1
    sent = [index for node in nodes for index in node.sent]
    assert sorted(sent) == list(range(len(collection)))
    assert scheduler.tests_finished
    # Whole recordings per worker, and both workers used.
    recordings = [set(_recordings(collection, node)) for node in nodes]
    assert not recordings[0] & recordings[1]
    assert all(recordings)


def test_a_few_large_specs_are_shared_evenly() -> None:
    collection = [f"spec{s}.hevval.yaml::signal{i}" for s in range(4) for i in range(5)]
    _, (first, second) = _start(collection, workers=2)
    assert len(first.sent) == len(second.sent) == 10
