"""The plants compute without BLAS or LAPACK (whose kernels round per CPU; docs/results.md,
"Reproducibility across machines").

* statically: no module of plant/ (its test oracles ``reference.py`` aside) has a ``@`` product,
  a call through ``np.dot``/``matmul``/``einsum``/``linalg``/``leggauss``, a scipy import or a
  BLAS/LAPACK address (numba compiles those into calls of scipy's OpenBLAS, which no
  monkeypatch sees), read with :mod:`ast`; the scanner is shown to find each kind;
* at run time: a ``disturbed`` cell, a ``compliant`` cell and a disturbed two-mass pulse train
  run with numpy's and scipy's linear-algebra entry points made to fail, the plants' set-up
  caches cleared first (so the modal forms and noise factors are built under the guard).
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

ROOT = Path(__file__).resolve().parent.parent
_BAD_ATTRS = {"dot", "matmul", "einsum", "inner", "vdot", "tensordot", "linalg", "leggauss",
              "get_cython_function_address", "cython_blas", "cython_lapack"}


def _findings(source: str) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            out.append(f"{node.lineno}: @")
        elif isinstance(node, ast.Attribute) and node.attr in _BAD_ATTRS:
            out.append(f"{node.lineno}: .{node.attr}")
        elif isinstance(node, ast.Name) and node.id == "get_cython_function_address":
            out.append(f"{node.lineno}: {node.id}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "cython_" in node.value:
            out.append(f"{node.lineno}: {node.value!r}")
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "scipy":
            out.append(f"{node.lineno}: from {node.module}")
        elif isinstance(node, ast.Import) and any(a.name.split(".")[0] == "scipy" for a in node.names):
            out.append(f"{node.lineno}: import scipy")
    return out


def test_the_scanner_finds_each_kind_of_blas_or_lapack_use():
    src = ("import scipy.linalg\nfrom scipy.linalg import expm\ny = A @ x\nz = np.dot(A, x)\n"
           "w, v = np.linalg.eigh(S)\nx, w = np.polynomial.legendre.leggauss(8)\n"
           "f = get_cython_function_address('scipy.linalg.cython_lapack', 'dpotrf')\n")
    got = _findings(src)
    for kind in ("import scipy", "from scipy.linalg", "@", ".dot", ".linalg", ".leggauss", "get_cython_function_address",
                 "'scipy.linalg.cython_lapack'"):
        assert any(kind in f for f in got), kind
    assert _findings("y = np.sum(a * b)\nz = np.exp(a)\n") == []


def test_no_plant_module_calls_blas_or_lapack():
    bad = {}
    for path in sorted((ROOT / "plant").rglob("*.py")):
        if path.name == "reference.py" or "identification" in path.parts:
            continue     # noise-free test oracles (solve_ivp) and the fit (scipy's optimizers)
        found = _findings(path.read_text())
        if found:
            bad[str(path.relative_to(ROOT))] = found
    assert bad == {}


def _boom(*args, **kwargs):
    raise AssertionError("BLAS/LAPACK on a plant's path")


@pytest.fixture
def no_linalg(monkeypatch):
    """numpy's and scipy's linear algebra made to fail, and the plants' set-up caches emptied."""
    from plant.multimode import disturbed, disturbed_jit
    from plant.two_mass import disturbed as tm_disturbed
    from plant.two_mass import interval as tm_interval

    for name in ("eig", "eigh", "eigvals", "eigvalsh", "inv", "pinv", "cholesky", "cond", "solve", "det", "svd",
                 "qr", "lstsq", "matrix_power", "norm"):
        monkeypatch.setattr(np.linalg, name, _boom)
    for name in ("eig", "eigh", "inv", "pinv", "cholesky", "solve", "det", "svd", "expm", "lu_factor", "qr"):
        monkeypatch.setattr(scipy.linalg, name, _boom)
    for name in ("dot", "matmul", "einsum", "inner", "vdot", "tensordot"):
        monkeypatch.setattr(np, name, _boom)
    for name in ("leggauss",):
        monkeypatch.setattr(np.polynomial.legendre, name, _boom)
    tm_interval.plan.cache_clear()
    for f in (tm_disturbed._cache, tm_disturbed._modal, tm_disturbed._moving_modal, disturbed._cache):
        f.cache_clear()
    monkeypatch.setattr(disturbed_jit._LOCAL, "memo", {}, raising=False)
    monkeypatch.setattr(disturbed_jit._LOCAL, "last", None, raising=False)
    yield
    tm_interval.plan.cache_clear()


@pytest.mark.parametrize("scenario, controller", [("disturbed", "solnic"), ("disturbed", "linear"),
                                                  ("compliant", "pulse-width"), ("compliant", "linear")])
def test_disturbed_and_compliant_cells_run_without_blas_or_lapack(no_linalg, scenario, controller):
    from bench.runner import run_closed_loop
    from bench.scenarios import builtin_scenarios
    from controllers import make_controller

    s = builtin_scenarios()[scenario]
    r = run_closed_loop(s.params, make_controller(controller), duration_s=3.0, warmup_s=0.5, seed=0,
                        family=s.family, model=s.model)
    assert r.status == "ok", r.message
    assert r.metrics["n_events"] > 0 or controller == "linear"


def test_a_disturbed_two_mass_pulse_train_runs_without_blas_or_lapack(no_linalg):
    from bench.scenarios import builtin_scenarios
    from plant import DriveCommand, DriveType
    from plant.randomness import NoiseStream
    from plant.state import SimOptions
    from plant.two_mass import disturbed as tm_disturbed

    p = dataclasses.replace(builtin_scenarios()["compliant"].params, disturbance_torque_std=0.28,
                            disturbance_torque_tau=0.02)
    ns = NoiseStream.from_seed(0)
    s = tm_disturbed.initial_state(p, 0.0)
    events = 0
    for k in range(40):
        lvl = p.u_max if k % 6 == 0 else -p.u_max if k % 6 == 3 else 0.0
        for noise in (ns, None):
            r = tm_disturbed.advance(s, DriveCommand.hold(lvl, DriveType.BRIDGE), p, noise, SimOptions(noise=noise is not None))
            assert r.status.value == "ok", r.message
        s = r.state
        events += r.n_events
    assert events > 0
