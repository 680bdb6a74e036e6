"""The log of a real axis (SPEC §11): ``t`` [s], ``u`` [ozf·in], ``y`` [rad] and a header.

CSV layout (the plan written by ``solnic-bench experiment`` is the same without ``y``)::

    # drive = linear            (or bridge)
    # sample_period = 0.01      (τs [s])
    # u_max = 20                (bridge only: the supply level [ozf·in])
    t [s],u [ozf*in],y [rad]
    0.00,0,1.3e-06
    0.01,0:5|0.006:0,2.1e-06    (a sample interval with segments "offset:level|offset:level")

``t`` must be the sample instants n·τs from 0 (no gap, increasing), ``u`` the drive level held
from each sample (or the segments inside its interval), ``y`` the measured angle. Parquet holds
the same columns with ``drive``, ``sample_period`` and ``u_max`` in the schema metadata.
Every defect is one :class:`LogError` naming the file, the row (file line) and the column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plant.drive import DriveCommand, DriveType

__all__ = ["AxisLog", "LogError", "read_log", "write_log", "COLUMNS"]

# column -> accepted unit spellings (the first is written)
COLUMNS = {"t": ("s",), "u": ("ozf*in", "ozf·in", "ozf.in"), "y": ("rad",)}
_T_TOL = 1e-6   # |t − n·τs| allowed, relative to τs


class LogError(ValueError):
    """A defect of a log or plan file; the message names file, row and column."""


@dataclass(frozen=True)
class AxisLog:
    """A log (or, with ``y`` None, a plan) of one axis experiment.

    Attributes
    ----------
    drive : {"linear", "bridge"}
    sample_period : float
        τs [s].
    u_max : float
        Bridge supply level [ozf·in] (for the linear drive: the largest |u| in the log).
    commands : tuple of DriveCommand
        The drive in each sample interval n (from t = n·τs).
    y : ndarray or None
        Measured angle y(n) [rad], one per sample instant.
    description : str
        Comment lines of the header (the plan's explanation).
    """

    drive: str
    sample_period: float
    u_max: float
    commands: tuple
    y: np.ndarray | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if self.drive not in ("linear", "bridge"):
            raise ValueError(f"AxisLog.drive must be 'linear' or 'bridge', got {self.drive!r}")
        if not (self.sample_period > 0 and math.isfinite(self.sample_period)):
            raise ValueError(f"AxisLog.sample_period must be a finite time > 0 s, got {self.sample_period!r}")
        if self.y is not None and len(self.y) != len(self.commands):
            raise ValueError(f"AxisLog.y must have one sample per command ({len(self.commands)}), got {len(self.y)}")

    @property
    def n(self) -> int:
        return len(self.commands)

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n) * self.sample_period

    def with_y(self, y: np.ndarray) -> "AxisLog":
        return AxisLog(self.drive, self.sample_period, self.u_max, self.commands, np.asarray(y, float), self.description)


def _fmt_u(cmd: DriveCommand) -> str:
    if len(cmd.segments) == 1:
        return repr(float(cmd.segments[0][1]))
    return "|".join(f"{o!r}:{v!r}" for o, v in cmd.segments)


def write_log(log: AxisLog, path: Path) -> Path:
    """Write ``log`` as CSV (or Parquet for a ``.parquet`` path); returns the path."""
    path = Path(path)
    u = [_fmt_u(c) for c in log.commands]
    t = [repr(round(n * log.sample_period, 12)) for n in range(log.n)]
    if path.suffix == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq
        cols = {"t [s]": pa.array(np.array(t, float)), "u [ozf*in]": pa.array(u)}
        if log.y is not None:
            cols["y [rad]"] = pa.array(np.asarray(log.y, float))
        meta = {"drive": log.drive, "sample_period": repr(log.sample_period), "u_max": repr(log.u_max)}
        pq.write_table(pa.table(cols).replace_schema_metadata(meta), path)
        return path
    lines = [f"# {line}".rstrip() for line in log.description.splitlines()]
    lines += [f"# drive = {log.drive}", f"# sample_period = {log.sample_period!r}", f"# u_max = {log.u_max!r}"]
    lines.append("t [s],u [ozf*in]" + (",y [rad]" if log.y is not None else ""))
    for n in range(log.n):
        row = f"{t[n]},{u[n]}" + (f",{float(log.y[n])!r}" if log.y is not None else "")
        lines.append(row)
    path.write_text("\n".join(lines) + "\n")
    return path


def _column(name: str, where: str) -> str:
    """The column key of a header cell ``name [unit]``; LogError for an unknown column or unit."""
    text = name.strip()
    key, unit = text, None
    if "[" in text and text.endswith("]"):
        key, unit = text[:text.index("[")].strip(), text[text.index("[") + 1:-1].strip()
    if key not in COLUMNS:
        raise LogError(f"{where}: column {text!r}: unknown column; expected "
                       f"{', '.join(f'{k} [{v[0]}]' for k, v in COLUMNS.items())}")
    if unit is None:
        raise LogError(f"{where}: column {key!r}: no unit; write '{key} [{COLUMNS[key][0]}]'")
    if unit not in COLUMNS[key]:
        raise LogError(f"{where}: column {key!r}: unit {unit!r} is wrong; expected {COLUMNS[key][0]!r}")
    return key


def _number(text: str, where: str, col: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise LogError(f"{where}: column {col!r}: {text.strip()!r} is not a number") from None
    if not math.isfinite(v):
        raise LogError(f"{where}: column {col!r}: {text.strip()!r} is not a finite number")
    return v


def _command(text: str, drive: DriveType, tau: float, u_max: float, where: str) -> DriveCommand:
    text = text.strip()
    if "|" not in text and ":" not in text:
        segs = [(0.0, _number(text, where, "u"))]
    else:
        segs = []
        for part in text.split("|"):
            if part.count(":") != 1:
                raise LogError(f"{where}: column 'u': segment {part!r} is not 'offset:level'")
            o, v = part.split(":")
            segs.append((_number(o, where, "u"), _number(v, where, "u")))
        offs = [o for o, _ in segs]
        if offs[0] != 0.0 or any(b <= a for a, b in zip(offs, offs[1:])) or offs[-1] >= tau:
            raise LogError(f"{where}: column 'u': segment offsets must start at 0, increase and stay "
                           f"below τs = {tau!r} s, got {offs}")
    if drive is DriveType.BRIDGE:
        for _, v in segs:
            if v not in (0.0, u_max, -u_max):
                raise LogError(f"{where}: column 'u': bridge level {v!r} is not one of 0, ±u_max = ±{u_max!r}")
    elif any(abs(v) > u_max for _, v in segs):
        raise LogError(f"{where}: column 'u': |level| exceeds u_max = {u_max!r}")
    return DriveCommand(segs, drive)


def _header_value(meta: dict, key: str, where: str) -> str:
    if key not in meta:
        raise LogError(f"{where}: header {key!r} missing (write '# {key} = ...')")
    return meta[key]


def _parse(path: Path, meta: dict, head: list[str], rows: list[tuple[int, list[str]]],
           description: str, want_y: bool) -> AxisLog:
    name = str(path)
    drive_text = _header_value(meta, "drive", f"{name}:header").strip()
    if drive_text not in ("linear", "bridge"):
        raise LogError(f"{name}:header: drive {drive_text!r} must be 'linear' or 'bridge'")
    tau = _number(_header_value(meta, "sample_period", f"{name}:header"), f"{name}:header", "sample_period")
    if not (0 < tau <= 10):
        raise LogError(f"{name}:header: sample_period {tau!r} s must be in (0, 10]")
    drive = DriveType(drive_text)
    u_max = math.inf
    if "u_max" in meta:
        u_max = _number(meta["u_max"], f"{name}:header", "u_max")
        if not u_max > 0:
            raise LogError(f"{name}:header: u_max {u_max!r} must be > 0 ozf·in")
    elif drive is DriveType.BRIDGE:
        _header_value(meta, "u_max", f"{name}:header")
    hline, cells = head[0], head[1]
    keys = [_column(c, f"{name}:{hline}") for c in cells]
    for k in ("t", "u") + (("y",) if want_y else ()):
        if k not in keys:
            raise LogError(f"{name}:{hline}: column {k!r} missing (expected t [s], u [ozf*in]"
                           f"{', y [rad]' if want_y else ''})")
    if len(set(keys)) != len(keys):
        raise LogError(f"{name}:{hline}: a column appears twice: {cells}")
    it, iu = keys.index("t"), keys.index("u")
    iy = keys.index("y") if "y" in keys else None
    if not rows:
        raise LogError(f"{name}:{hline}: no samples")
    cmds, ys, t_prev = [], [], None
    for n, (line, vals) in enumerate(rows):
        where = f"{name}:{line}"
        if len(vals) != len(keys):
            raise LogError(f"{where}: {len(vals)} values for {len(keys)} columns {cells}")
        t = _number(vals[it], where, "t")
        if t_prev is not None and not t > t_prev:
            raise LogError(f"{where}: column 't': t = {t!r} s is not after the previous sample's {t_prev!r} s")
        if abs(t - n * tau) > _T_TOL * tau:
            if t_prev is not None and t > t_prev + 1.5 * tau:
                raise LogError(f"{where}: column 't': missing sample(s) between t = {t_prev!r} s and {t!r} s "
                               f"(τs = {tau!r} s)")
            raise LogError(f"{where}: column 't': t = {t!r} s is not the sample instant {n * tau!r} s "
                           f"(sample {n}, τs = {tau!r} s, from 0)")
        t_prev = t
        cmds.append(_command(vals[iu], drive, tau, u_max, where))
        if iy is not None:
            ys.append(_number(vals[iy], where, "y"))
    if not math.isfinite(u_max):
        u_max = max(max(abs(v) for _, v in c.segments) for c in cmds) or 1.0
    y = np.array(ys) if (iy is not None and want_y) else None
    return AxisLog(drive_text, tau, u_max, tuple(cmds), y, description)


def read_log(path: Path | str, *, want_y: bool = True) -> AxisLog:
    """Read a log (``want_y``) or a plan from CSV or Parquet.

    Raises
    ------
    LogError
        One line naming the file, the row (line) and the column: missing samples, non-monotone
        t, NaN, an unknown column, a wrong unit, a bad header or drive level.
    """
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    if path.suffix == ".parquet":
        return _read_parquet(path, want_y)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: cannot read: {exc}") from None
    meta: dict[str, str] = {}
    desc: list[str] = []
    head = None
    rows: list[tuple[int, list[str]]] = []
    for i, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            k, sep, v = body.partition("=")
            if sep and k.strip() in ("drive", "sample_period", "u_max", "max_angle", "max_torque"):
                meta[k.strip()] = v.split("#")[0].strip()
            elif head is None:
                desc.append(body)
            continue
        cells = [c.strip() for c in line.split(",")]
        if head is None:
            head = (i, cells)
        else:
            rows.append((i, cells))
    if head is None:
        raise LogError(f"{path}:1: no column header (t [s],u [ozf*in],y [rad])")
    return _parse(path, meta, head, rows, "\n".join(desc), want_y)


def _read_parquet(path: Path, want_y: bool) -> AxisLog:
    import pyarrow.parquet as pq
    try:
        table = pq.read_table(path)
    except Exception as exc:   # pyarrow raises several types for a corrupt file
        raise LogError(f"{path}: not a readable Parquet file: {' '.join(str(exc).split())}") from None
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}
    cells = table.column_names
    cols = [table.column(c).to_pylist() for c in cells]
    rows = [(r + 1, ["nan" if col[r] is None else str(col[r]) for col in cols]) for r in range(table.num_rows)]
    return _parse(path, meta, (0, cells), rows, "", want_y)
