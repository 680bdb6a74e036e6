"""The results store of a run directory.

Layout of ``DIR``:

* ``cells/<cell>.json`` — one finished cell's results row, written atomically (temporary file,
  fsync, ``os.replace``) as soon as the cell finishes. This is the source of truth: a killed run
  loses at most the cells in flight.
* ``results.parquet``, ``results.csv`` — one row per cell of the current matrix, rebuilt
  atomically from the cell files after a run (and on resume). Never appended to, so never
  duplicated.
* ``.lock`` — held (``flock``) while a run writes, so two runs cannot share a directory.

A cell counts as done when its file holds the same ``config_hash`` (and, when traces are wanted,
its trace exists); anything else — missing, unreadable, another configuration — is recomputed.
An ``error`` row is done only if its cause was the configuration (``error_kind`` ``run``) and it
ran under the same ``time_limit_s``; a time-limit stop, a dead cell process or a failed artifact
depend on the machine and are run again.

A run directory belongs to one matrix definition (:meth:`ResultsStore.check_matrix`): every
stored cell must be a cell of the new matrix with the same *definition hash* (controller,
options, scenario, plant, seed, run length, warm-up, plugins). A second, different matrix into the
same directory is refused as a user error before anything is written; a grown matrix (more
seeds, controllers or scenarios) and changed code (edited simulator or plugin source: same
definition, new config hash, so the cell is recomputed) are accepted.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pandas as pd

from bench.cells import LEADING_COLUMNS, Cell
from bench.errors import UserError
from bench.names import check_cell_id

__all__ = ["ResultsStore", "StoreBusy", "RunDirConflict", "write_atomic", "results_frame", "check_layout"]


class StoreBusy(UserError):
    """Another run holds the directory's lock."""


class RunDirConflict(UserError):
    """The run directory holds results of another matrix definition."""


def check_layout(root: Path) -> None:
    """The run directory's entries have the right types (a user error otherwise, before any write)."""
    root = Path(root)
    for name, want_dir in (("cells", True), ("traces", True), ("series", True), ("results.parquet", False),
                           ("results.csv", False), ("config.json", False), ("meta.json", False),
                           ("report.html", False), (".lock", False)):
        p = root / name
        if p.exists() or p.is_symlink():
            if want_dir and not p.is_dir():
                raise UserError(f"{p}: exists and is not a directory; move it away or use another --out")
            if not want_dir and not p.is_file():
                raise UserError(f"{p}: exists and is not a regular file; move it away or use another --out")


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same directory and ``os.replace``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _column(values: list[Any]) -> pd.Series:
    """One consistent type per column so parquet accepts it: bool, Int64, float or string."""
    present = [v for v in values if not _missing(v)]
    if all(isinstance(v, bool) for v in present) and present:
        return pd.Series([pd.NA if _missing(v) else v for v in values], dtype="boolean")
    if (present and all(isinstance(v, int) and not isinstance(v, bool) and -2**63 <= v < 2**63 for v in present)):
        return pd.Series([pd.NA if _missing(v) else v for v in values], dtype="Int64")
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return pd.Series([math.nan if _missing(v) else _float(v) for v in values], dtype=float)
    return pd.Series([None if _missing(v) else str(v) for v in values], dtype="string")


def _float(v: int | float) -> float:
    try:
        return float(v)
    except OverflowError:  # an integer beyond 1.8e308
        return math.inf if v > 0 else -math.inf


_TEXT = ("cell", "controller", "scenario", "status", "message", "controller_base", "scenario_base",
         "config_hash", "code_version", "error_kind", "definition_hash")


def results_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows → DataFrame: the leading columns first, the rest (``ctl_*`` ...) sorted."""
    if not rows:
        return pd.DataFrame(columns=list(LEADING_COLUMNS))
    names = {k for row in rows for k in row}
    order = [c for c in LEADING_COLUMNS if c in names] + sorted(names - set(LEADING_COLUMNS))
    data: dict[str, pd.Series] = {}
    for col in order:
        values = [row.get(col) for row in rows]
        if col == "seed":
            data[col] = pd.Series(values, dtype="int64")
        elif col in _TEXT:
            data[col] = pd.Series(["" if _missing(v) else str(v) for v in values], dtype=str)
        else:
            data[col] = _column(values)
    return pd.DataFrame(data)


class ResultsStore:
    """Cell files and rebuilt tables of one run directory."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.cells_dir = self.root / "cells"

    def cell_path(self, cell_id: str) -> Path:
        return self.cells_dir / f"{check_cell_id(cell_id)}.json"

    def trace_path(self, cell_id: str) -> Path:
        return self.root / "traces" / f"{check_cell_id(cell_id)}.rrd"

    def load(self, cell: Cell) -> dict[str, Any] | None:
        """The stored row of ``cell`` if it has the same config hash, else None."""
        try:
            row = json.loads(self.cell_path(cell.cell_id).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(row, dict) or row.get("config_hash") != cell.config_hash:
            return None
        return row

    def is_done(self, cell: Cell, traces: bool) -> bool:
        """Stored with the same hash (and its trace, if wanted). An ``error`` row is done only if
        the configuration caused it (``error_kind`` ``run``) under the same ``time_limit_s``: a
        wall-clock stop, a dead process or a failed artifact depend on the machine, and an error
        under another limit may not recur, so a resume runs those again."""
        row = self.load(cell)
        if row is None or (traces and not self.trace_path(cell.cell_id).is_file()):
            return False
        if row.get("status") != "error":
            return True
        kind = row.get("error_kind")
        if kind is None:   # a row of an older version: the message is all there is
            return "time limit" not in str(row.get("message", ""))
        limit = row.get("time_limit_s")
        same_limit = (cell.time_limit_s is None and _missing(limit)) or limit == cell.time_limit_s
        return kind == "run" and same_limit

    def check_matrix(self, cells: Iterable[Cell]) -> None:
        """Refuse a matrix that would overwrite or drop stored cells of another definition.

        Raises
        ------
        RunDirConflict
            A stored cell is not in ``cells``, or has another definition hash.
        """
        wanted = {c.cell_id: c for c in cells}
        if not self.cells_dir.is_dir():
            return
        for path in sorted(self.cells_dir.glob("*.json")):
            try:
                row = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue    # unreadable: it will be recomputed or ignored
            if not isinstance(row, dict):
                continue
            cell_id = str(row.get("cell", path.stem))
            cell = wanted.get(cell_id)
            hint = "use another --out (a run directory holds one matrix; it may only grow)"
            if cell is None:
                raise RunDirConflict(f"{self.root}: holds cell {cell_id!r}, which this matrix does not have; {hint}")
            stored = row.get("definition_hash")
            if stored is not None and stored != cell.definition_hash:
                raise RunDirConflict(f"{self.root}: cell {cell_id!r} was run with another definition "
                                     f"({_difference(row, cell)}); {hint}")

    def save(self, row: dict[str, Any]) -> Path:
        """Store one finished cell atomically."""
        path = self.cell_path(row["cell"])
        write_atomic(path, json.dumps(row, sort_keys=True, allow_nan=True, indent=1))
        return path

    def rows(self, cells: Iterable[Cell]) -> list[dict[str, Any]]:
        """Stored rows of ``cells`` (in their order), skipping cells not done."""
        return [row for row in (self.load(c) for c in cells) if row is not None]

    def rebuild(self, cells: Iterable[Cell]) -> pd.DataFrame:
        """Rewrite ``results.parquet`` and ``results.csv`` from the cell files of ``cells``."""
        df = results_frame(self.rows(cells))
        self.root.mkdir(parents=True, exist_ok=True)
        with _scratch(self.root, "results.parquet") as tmp:
            df.to_parquet(tmp, index=False)
            os.chmod(tmp, 0o644)
            os.replace(tmp, self.root / "results.parquet")
        write_atomic(self.root / "results.csv", df.to_csv(index=False))
        return df

    def write_json(self, name: str, obj: Any) -> Path:
        path = self.root / name
        write_atomic(path, json.dumps(obj, indent=2, sort_keys=False, allow_nan=True, default=str) + "\n")
        return path

    def clean_temporaries(self) -> int:
        """Remove temporary files left by a killed run (only call while holding the lock)."""
        removed = 0
        for sub in (self.root, self.cells_dir, self.root / "traces", self.root / "series"):
            if sub.is_dir():
                for p in sub.glob(".*.tmp"):
                    p.unlink(missing_ok=True)
                    removed += 1
        return removed

    @contextlib.contextmanager
    def lock(self) -> Iterator[None]:
        """Hold ``DIR/.lock`` for the duration; :class:`StoreBusy` if another run holds it."""
        self.root.mkdir(parents=True, exist_ok=True)
        fh = open(self.root / ".lock", "a+")
        try:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise StoreBusy(f"{self.root}: another solnic-bench run is using this directory") from None
            yield
        finally:
            fh.close()


def _difference(row: dict[str, Any], cell: Cell) -> str:
    """A short description of how a stored row differs from ``cell`` (for the refusal message)."""
    for key, now in (("duration_s", cell.duration_s), ("warmup_s", cell.warmup_s),
                     ("controller_base", cell.controller.base), ("scenario_base", cell.scenario.base)):
        if key in row and row[key] != now:
            return f"{key} {row[key]!r}, now {now!r}"
    return "controller options, plant parameters or plugins differ"


@contextlib.contextmanager
def _scratch(directory: Path, name: str) -> Iterator[Path]:
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
    os.close(fd)
    try:
        yield Path(tmp)
    finally:
        Path(tmp).unlink(missing_ok=True)
