"""pytest configuration of the suite; the shared helpers are in ``helpers.py``.

The suite runs on pytest-xdist's workers (``-n auto --dist worksteal`` in pyproject.toml): each worker
takes a contiguous share of the collection and an idle one steals the tail of another's queue.  A slow
test met last would be run alone while the other workers wait, so under xdist the tests marked
``slow`` (each takes seconds to minutes) are collected first, in their usual order, and the many
quick ones fill the gaps and the end.  A serial run keeps the usual order.
"""

import pytest


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    if not hasattr(config, "workerinput"):  # not an xdist worker: the usual order
        return
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)  # stable: slow ones first
