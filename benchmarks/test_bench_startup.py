"""Start-up of the ``solnic-bench`` program (issue 27 item 3): a command pays only for what it runs.

Target: ``solnic-bench --help`` ≤ 0.5 s wall (it was ~1.9 s when every command's module imported
numba, scipy, pandas and the plant eagerly; 0.11–0.15 s after, on a loaded 2-core machine).
Each body also checks what the process imported, so ``make test`` (benchmarks disabled, one
call each) catches an eager heavy import coming back.
"""

import subprocess
import sys

import pytest

# Modules a command's --help never needs; importing any of them costs 0.1–0.6 s.
HEAVY = ("numba", "scipy", "pandas", "pyarrow", "plotly", "dask", "plant.multimode")

_PROBE = """
import sys
from reports.cli import main
try:
    main({argv!r})
except SystemExit as exc:
    code = exc.code
else:
    code = 0
heavy = sorted(m for m in {heavy!r} if m in sys.modules)
print("PROBE", code, ",".join(heavy), file=sys.stderr)
"""


def _run(argv: list[str], heavy: tuple[str, ...] = HEAVY) -> tuple[int, list[str], str]:
    """Run ``solnic-bench argv`` in a fresh interpreter; its exit code, the ``heavy`` modules it
    imported, and its stdout."""
    proc = subprocess.run([sys.executable, "-c", _PROBE.format(argv=argv, heavy=heavy)],
                          capture_output=True, text=True, timeout=120)
    probe = [line for line in proc.stderr.splitlines() if line.startswith("PROBE ")]
    assert probe, proc.stderr[-2000:]
    _, code, heavy = (probe[-1].split(" ") + [""])[:3]
    return int(code or 0), [m for m in heavy.split(",") if m], proc.stdout


@pytest.mark.parametrize("argv", [["--help"], ["speed", "--help"], ["check-bound", "--help"],
                                  ["run", "--help"], ["frontier", "--help"]],
                         ids=lambda a: " ".join(a))
def test_help_imports_nothing_heavy(benchmark, argv):
    code, heavy, out = benchmark.pedantic(_run, args=(argv,), rounds=3, iterations=1)
    assert code == 0
    assert "Usage" in out
    assert heavy == [], f"solnic-bench {' '.join(argv)} imported {heavy}"


def test_list_imports_no_registry_once_cached(benchmark):
    """``list`` prints the registries' listing; once a process has built it for this source
    (bench.list_command's cache), a later ``list`` imports no controller, no plant family, no
    numba or scipy (measured on a loaded 2-core machine: ~1.2× ``--help`` against ~10× before)."""
    code, _, first = _run(["list"])                   # builds the listing (or finds it)
    assert code == 0
    registries = HEAVY + ("controllers.base", "plant.protocol")
    code, heavy, out = benchmark.pedantic(_run, args=(["list"], registries), rounds=3, iterations=1)
    assert code == 0 and out == first
    assert "controllers" in out and "default matrix:" in out and "frontier:" in out
    assert heavy == [], f"solnic-bench list imported {heavy}"
