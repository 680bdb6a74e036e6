"""Test-session hooks: the long files first.

``make test`` runs two pytest-xdist workers with ``--dist loadfile`` (a file's tests on one
worker, its module fixtures computed once). The workers take files in collection order, so a
long file collected last keeps one worker busy after the other has finished. Files with a test
marked ``slow`` (end-to-end CLI runs, closed-loop replays, Monte-Carlo checks) go first — the
longest-processing-time-first rule — and the order is otherwise unchanged.
"""

from __future__ import annotations


def pytest_collection_modifyitems(session, config, items):
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.path not in slow)        # stable: file order kept within each class
