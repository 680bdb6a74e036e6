"""``solnic-bench list``'s cached listing (bench.list_command, issue 27 item 3): it is the
registries' own listing, and any change of the source it was built from invalidates it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bench import list_command as lc


def test_cached_listing_is_the_registries_listing(tmp_path):
    """A fresh process writes the cache (or reads it); it must equal what the registries give now."""
    proc = subprocess.run([sys.executable, "-m", "reports.cli", "list"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    key = lc._source_digest()
    assert key is not None
    cache = next((lc.Path(lc.__file__).resolve().parent / "__pycache__").glob(f"list-{key}.json"), None)
    if cache is None:
        pytest.skip("bench/__pycache__ is not writable here: no cache to check")
    cached = json.loads(cache.read_text())
    assert cached == json.loads(json.dumps(lc._listing(None)))
    from controllers.base import available_controllers

    assert [row[0] for row in cached["controllers"]] == list(available_controllers())
    assert any(line.startswith("default matrix:") for line in cached["lines"])


def test_source_digest_changes_with_any_source_file(tmp_path, monkeypatch):
    pkg = tmp_path / "listpkg_probe"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("A = 1\n")
    (pkg / "sub" / "m.toml").write_text("[x]\n")
    (pkg / "notes.txt").write_text("not source\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(lc, "_SOURCE_PACKAGES", ("listpkg_probe",))
    first = lc._source_digest()
    (pkg / "notes.txt").write_text("changed, but not source\n")
    assert lc._source_digest() == first
    (pkg / "sub" / "m.toml").write_text("[x]\ny = 1\n")
    second = lc._source_digest()
    assert second != first
    (pkg / "sub" / "new.py").write_text("")
    assert lc._source_digest() not in (first, second)
    assert "listpkg_probe" not in sys.modules          # found, never imported


def test_cache_is_not_used_once_a_registry_is_imported(monkeypatch):
    """In a process that imported the registries (a plugin may have registered more), the
    listing is built afresh."""
    import controllers.base  # noqa: F401

    calls = []
    monkeypatch.setattr(lc, "_listing", lambda spec: calls.append(spec) or {"x": 1})
    monkeypatch.setattr(lc, "_source_digest", lambda: pytest.fail("the cache must not be consulted"))
    assert lc._cached_listing() == {"x": 1} and calls == [None]
