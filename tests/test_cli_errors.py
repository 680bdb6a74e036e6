"""More user errors, in-process through typer's runner: exit code 2, one line, nothing written."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from reports.cli import app

CASES = [
    (["run", "--matrix", "m.toml", "--quick"], None, "--matrix and --quick exclude each other"),
    (["run", "--quick", "--executor", "threads"], None, "--executor must be one of ['local', 'dask'], got 'threads'"),
    (["run", "--quick", "--scheduler", "tcp://127.0.0.1:1"], None, "--scheduler needs --executor dask"),
    (["run", "--quick", "--workers", "-3"], None, "--workers must be an integer >= 1, got -3"),
    (["run", "--matrix", "missing.toml"], None, "missing.toml: cannot read the matrix file"),
    (["run", "--matrix", "m.toml"], '[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0.5]\n',
     "m.toml: matrix.seeds: must be a non-empty list of integers in [0, 2**63)"),
    (["run", "--matrix", "m.toml"], '[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\n'
     'duration_s = -1\n', "m.toml: matrix.duration_s: must be > 0, got -1"),
    (["run", "--matrix", "m.toml"], '[matrix]\ncontrollers = ["v"]\nscenarios = ["thesis"]\nseeds = [0]\n'
     '[controllers.v]\nbase = "dithered"\ndither_frequency = 0\n',
     "m.toml: controllers.v.dither_frequency: dither_frequency must be > 0 Hz, got 0"),
    (["run", "--matrix", "m.toml"], '[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\n'
     '[plant]\ninertia = 1\n', "m.toml: plant: unknown table"),
    (["list", "--matrix", "m.toml"], '[matrix]\ncontrollers = ["linear"]\n', "m.toml: matrix.scenarios: is required"),
    (["report", "no-such-dir"], None, "no-such-dir: no such run directory"),
]


@pytest.mark.parametrize("args, matrix, message", CASES)
def test_user_error(tmp_path, monkeypatch, args, matrix, message):
    monkeypatch.chdir(tmp_path)
    if matrix is not None:
        (tmp_path / "m.toml").write_text(matrix)
    result = CliRunner().invoke(app, [*args, *(["--out", "out"] if args[0] == "run" else [])])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert lines == [f"error: {message}"] or (len(lines) == 1 and lines[0].startswith(f"error: {message}")), lines
    assert not (tmp_path / "out").exists()


def test_seed_beyond_int64_is_a_user_error(tmp_path):
    """tomllib accepts any integer; seeds must fit the results table's int64 column."""
    from bench.errors import UserError
    from bench.matrix import load_matrix

    f = tmp_path / "m.toml"
    f.write_text('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [18446744073709551616]\n')
    with pytest.raises(UserError, match=r"matrix\.seeds"):
        load_matrix(f)


def test_check_bound_out_is_a_file_is_a_user_error(tmp_path):
    from bench.bound import check_bound
    from bench.errors import UserError

    f = tmp_path / "not-a-dir"
    f.write_text("x")
    with pytest.raises(UserError, match="not a directory"):
        check_bound(quick=True, out_dir=f, tiny=True)
