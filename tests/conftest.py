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


import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _registries_restored():
    """Tests that run the CLI in-process import plugins, which register controllers and plant
    families: restore both registries after each test module so that no other file sees them."""
    from controllers.base import _REGISTRY as controllers, available_controllers
    from plant.protocol import BUILTIN_FAMILIES, _REGISTRY as families, get_family

    available_controllers()                # the built-ins are registered lazily: load them first
    for name in BUILTIN_FAMILIES:
        get_family(name)
    saved = dict(controllers), dict(families)
    yield
    for registry, before in zip((controllers, families), saved):
        registry.clear()
        registry.update(before)
