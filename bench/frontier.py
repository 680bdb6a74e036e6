"""``solnic-bench frontier``: every registered controller swept over its knob (issue 14).

The built-in matrices ``bench/matrices/frontier.toml`` and ``frontier-quick.toml`` declare the
scenarios, the shared seeds, the noise sweeps and explicit sweeps for controllers that do not
declare ``knobs`` yet. :func:`frontier_matrix_data` completes them from the registry:

* every registered controller is in the matrix (the ``privileged`` bounds too, drawn as floors);
* a controller whose class declares ``knobs`` is swept over them (the full frontier: every
  value of the first knob crossed with the first, middle and last value of the second;
  ``--quick``: the first, middle and last value of the first knob), replacing the file's
  explicit sweep; one without knobs keeps the file's sweep, or runs at its defaults;
* real controllers also keep their default point (``include_default``).

``--matrix FILE`` takes the matrix from FILE instead (e.g. the ``axis.toml`` that ``identify``
writes): its controllers, scenarios, seeds, run length and sweeps, completed from the registry
the same way (``--quick`` then thins the knobs as above). A bad FILE is one line naming it, exit 2.

The completed matrix is written to ``DIR/frontier-matrix.toml`` (what ran, for provenance and
``solnic-bench run --matrix`` reuse) and run like any matrix: same store, resume, executors; rerun
traces are off unless ``--traces``.
"""

from __future__ import annotations

import json
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Callable, Optional

import typer

from bench.cli import out_dir, user_errors, writable_dir
from bench.errors import UserError

__all__ = ["write_completed_matrix", "frontier_matrix_path", "frontier_matrix_data", "to_toml", "make_frontier_command", "thin"]


def frontier_matrix_path(quick: bool = False) -> Path:
    """``bench/matrices/frontier-quick.toml`` or ``frontier.toml`` (package data)."""
    name = "frontier-quick.toml" if quick else "frontier.toml"
    return Path(str(resources.files("bench").joinpath("matrices", name)))


def thin(values: tuple | list) -> list:
    """First, middle and last of ``values`` (all of them when there are at most three)."""
    values = list(values)
    if len(values) <= 3:
        return values
    return [values[0], values[len(values) // 2], values[-1]]


def frontier_matrix_data(quick: bool = False, source: Path | None = None) -> dict[str, Any]:
    """The frontier matrix as TOML data, completed from the controller registry (module doc);
    ``source``: a user's matrix file instead of the built-in one (validated first:
    :class:`bench.matrix.MatrixError` names the file and line)."""
    from controllers.base import available_controllers

    if source is None:
        data = tomllib.loads(frontier_matrix_path(quick).read_text(encoding="utf-8"))
    else:
        from bench.matrix import load_matrix

        parsed = load_matrix(source, check_resets=False)   # file:line errors before any completion
        data = tomllib.loads(Path(source).read_text(encoding="utf-8-sig"))
        if parsed.plugin_dirs:   # the completed file lives in DIR: keep finding the plugins where they are
            data["matrix"]["plugin_dirs"] = [str(Path(d).resolve()) for d in parsed.plugin_dirs]
    matrix = data["matrix"]
    sweep = data.setdefault("sweep", {})
    names = list(matrix["controllers"])
    registered = available_controllers()
    names += [n for n in registered if n not in names]
    matrix["controllers"] = names
    for name in names:
        cls = registered.get(name)
        if cls is None:
            continue
        knobs = dict(getattr(cls, "knobs", {}) or {})
        if knobs:
            fields = list(knobs)[:1] if quick else list(knobs)[:2]
            table = {f: (thin(knobs[f]) if quick or i > 0 else list(knobs[f])) for i, f in enumerate(fields)}
            table = {f: [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in vs]
                     for f, vs in table.items()}
            sweep[name] = table
        if name in sweep and not getattr(cls, "privileged", False):
            sweep[name]["include_default"] = True
    return data


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as a TOML value")


def _toml_key(k: str) -> str:
    return k if k and all(c.isalnum() or c in "-_" for c in k) else json.dumps(k)


def to_toml(data: dict[str, Any], header: str = "") -> str:
    """TOML text of matrix ``data`` (tables of scalars and lists, one nesting level of
    ``[table.name]``), which ``tomllib`` reads back to the same data."""
    out = [header] if header else []

    def emit(path: list[str], table: dict[str, Any]) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
        subs = {k: v for k, v in table.items() if isinstance(v, dict)}
        if scalars or not subs:
            out.append(f"[{'.'.join(_toml_key(p) for p in path)}]")
            out.extend(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in scalars.items())
            out.append("")
        for k, v in subs.items():
            emit(path + [k], v)

    for name, table in data.items():
        emit([name], table)
    return "\n".join(out) + "\n"


def write_completed_matrix(out: Path, name: str, text: str) -> Path:
    """Write a completed matrix file ``out/name`` (untouched when it already holds ``text``, so a
    resumed run keeps its file); an OSError is a user error naming ``--out``."""
    path = out / name
    try:
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write {path.name}: {exc.strerror or exc}") from None
    return path


def make_frontier_command(run: Callable[..., None]) -> Callable[..., None]:
    """The ``frontier`` command: writes the completed matrix, then runs it with ``run`` (the
    ``run`` command of :func:`bench.run_command.make_run_command`)."""

    @user_errors
    def frontier_command(
        quick: bool = typer.Option(False, "--quick", help="The quick frontier (at most 3 min on 2 cores)."),
        out_value: str = typer.Option("frontier", "--out", help="Run directory; a re-run resumes it."),
        executor: str = typer.Option("local", "--executor", help="local (process pool) or dask."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="dask scheduler address (default: a LocalCluster)."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: CPU count)."),
        traces: bool = typer.Option(False, "--traces", help="Also write a rerun trace per cell (off: thousands of cells)."),
        matrix: Optional[Path] = typer.Option(None, "--matrix", help="A matrix file instead of the built-in "
                                              "frontier (e.g. identify's axis.toml); completed from the registry."),
    ) -> None:
        """Every registered controller over its knob, with the oracle floor and the noise sweeps:
        DIR/results.{parquet,csv}, DIR/frontier-matrix.toml, DIR/report.html with a frontier section."""
        from bench.matrix import parse_matrix

        out = out_dir(out_value)
        data = frontier_matrix_data(quick) if matrix is None else frontier_matrix_data(quick, matrix)
        source = frontier_matrix_path(quick) if matrix is None else matrix
        parse_matrix(data, str(source), check_resets=False)   # a bad registry knob is a user error now; run() resets
        writable_dir(out)
        path = write_completed_matrix(out, "frontier-matrix.toml", to_toml(
            data, f"# Generated by `solnic-bench frontier{' --quick' if quick else ''}` "
                  f"from {source.name} and the controller registry."))
        run(matrix=path, quick=False, out_value=str(out), executor=executor, scheduler=scheduler, workers=workers,
            traces_policy="all" if traces else "none", no_traces=False)

    return frontier_command
