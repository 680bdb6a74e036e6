"""Keep numba's on-disk cache of the compiled plant consistent with the plant's source.

numba's ``cache=True`` checks only the file that defines a compiled function, not the modules
it calls: edit ``plant/multimode/zero_velocity.py`` and ``plant.multimode.interval.interval_kernel`` would still
load its cached machine code with the *old* callee inlined. Before any kernel is imported, this
compares a digest of every ``plant/**/*.py`` with the one stored in ``plant/__pycache__`` and
drops the cached kernels of every plant folder (the families' too) when they differ. A fresh checkout has no cache; this only matters to someone
editing the plant. :mod:`controllers` calls it for its own folder (the compiled controller steps
call helpers in other files of that package the same way).
"""

from __future__ import annotations

import hashlib
from pathlib import Path


def refresh(package: Path | None = None) -> None:
    """Drop the cached kernels of ``package`` (default: ``plant``) when its source changed."""
    here = package if package is not None else Path(__file__).resolve().parent
    cache = here / "__pycache__"
    digest = hashlib.sha256()
    for src in sorted(here.rglob("*.py")):
        digest.update(src.relative_to(here).as_posix().encode())
        digest.update(src.read_bytes())
    stamp = cache / "numba-source.sha256"
    value = digest.hexdigest()
    try:
        if stamp.read_text() == value:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for stale in list(here.rglob("__pycache__/*.nbi")) + list(here.rglob("__pycache__/*.nbc")):
            stale.unlink(missing_ok=True)
        stamp.write_text(value)
    except OSError:          # a read-only install: numba falls back to compiling in memory
        pass
