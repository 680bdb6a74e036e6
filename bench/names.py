"""Names that become file names: one check for every controller and scenario name of a matrix.

A cell's id ``<controller>__<scenario>__s<seed>`` is the stem of its files in the run
directory (``cells/<id>.json``, ``traces/<id>.rrd``, ``series/<id>.parquet``, and their
temporary names ``.<id>.<suffix>.<token>.tmp``), so every name that reaches it — a registered
controller (also one a plugin registers), a variant, a sweep point (its swept values included),
a custom scenario — passes :func:`name_problem` before anything runs, and the store refuses a
cell id that does not (:func:`check_cell_id`): no file is ever written outside ``--out``.

Allowed: ASCII letters, digits and ``_ . + - [ ] = ,`` (the last four for sweep points such as
``linear[crossover=40,lag_ratio=3]``), starting with a letter or digit, without ``__`` (the
separator of the cell id) and at most :data:`MAX_NAME_CHARS` characters, so that the longest
temporary file name stays below the file systems' 255-byte limit.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

__all__ = ["MAX_NAME_CHARS", "MAX_OUT_CHARS", "name_problem", "check_cell_id", "out_dir_problem"]

MAX_NAME_CHARS = 80
# --out: the absolute path plus the longest relative path written below it must fit PATH_MAX (4096).
MAX_OUT_CHARS = 3500
_NAME_MAX_BYTES = 255
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+\-\[\]=,]*\Z")
_CELL_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+\-\[\]=,]*__[A-Za-z0-9][A-Za-z0-9_.+\-\[\]=,]*__s\d{1,19}\Z")


def name_problem(name: object) -> str | None:
    """Why ``name`` cannot name a controller or scenario (None if it can)."""
    if not isinstance(name, str):
        return f"name must be a string, got {name!r}"
    if len(name) > MAX_NAME_CHARS:
        return (f"name {name[:40]!r}... has {len(name)} characters; at most {MAX_NAME_CHARS} "
                f"(it is part of the cell's file names)")
    if not _NAME.match(name) or "__" in name:
        return (f"name {name!r} must start with a letter or digit, contain only ASCII letters, digits "
                f"and _ . + - [ ] = , and no '__' (it is part of the cell's file names)")
    return None


def check_cell_id(cell_id: str) -> str:
    """``cell_id`` if it is a plain file stem made of checked names, else ``ValueError``.

    The store and the cell's artifacts call this before building a path from a cell id: a name
    that bypassed the matrix check can still never write outside the run directory.
    """
    if not isinstance(cell_id, str) or len(cell_id) > 2 * MAX_NAME_CHARS + 24 or not _CELL_ID.match(cell_id):
        raise ValueError(f"cell id {cell_id!r} is not a plain file name made of checked names")
    return cell_id


def out_dir_problem(path: Path) -> str | None:
    """Why ``path`` cannot be a run directory because of its length (None if it can)."""
    text = str(path)
    for part in Path(text).parts:
        if len(os.fsencode(part)) > _NAME_MAX_BYTES:
            return (f"has a path component of {len(os.fsencode(part))} bytes; at most {_NAME_MAX_BYTES} "
                    f"(the file system's limit)")
    try:
        full = os.path.abspath(text)
    except (OSError, ValueError) as exc:
        return f"is not a usable path: {exc}"
    if len(os.fsencode(full)) > MAX_OUT_CHARS:
        return (f"is {len(os.fsencode(full))} bytes long as an absolute path; at most {MAX_OUT_CHARS} "
                f"(the cell files below it must fit the 4096-byte path limit)")
    return None
