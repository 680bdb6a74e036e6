"""docs/plant-family.md's example family, exactly as printed, through the real CLI.

The seam's promise: a new plant family is a module of its own (here a plugin) and runs
``run`` with a scenario sweep, and ``report``, without a change to bench/ or reports/.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


def _example(name: str) -> str:
    text = (ROOT / "docs" / "plant-family.md").read_text(encoding="utf-8")
    m = re.search(rf"<!-- example: {re.escape(name)} -->\n```\w+\n(.*?)\n```", text, re.S)
    assert m, f"docs/plant-family.md has no example block {name!r}"
    return m.group(1) + "\n"


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "reports.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.fixture(scope="module")
def example_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("family")
    (d / "viscous_plant.py").write_text(_example("viscous_plant.py"))
    (d / "viscous.toml").write_text(_example("viscous.toml"))
    return d


def test_example_family_runs_sweeps_and_reports_through_the_cli(example_dir):
    d = example_dir
    listed = _cli("list", "--matrix", d / "viscous.toml", cwd=d)
    assert listed.returncode == 0, listed.stderr
    assert "viscous" in listed.stdout
    run = _cli("run", "--matrix", d / "viscous.toml", "--out", d / "out", "--no-traces", cwd=d)
    assert run.returncode == 0, run.stderr
    df = pd.read_csv(d / "out" / "results.csv").set_index("cell")
    assert (df["status"] == "ok").all(), df["message"]
    damped = df[df["scenario_base"] == "thesis"].filter(like="damped", axis=0)
    assert len(damped) == 6 and (damped["plant_family"] == "viscous").all()
    assert df.loc["dithered__thesis__s0"].get("plant_family") is None or \
        pd.isna(df.loc["dithered__thesis__s0"]["plant_family"])
    # the damping reaches the shaft: more viscous friction, a different run on the same seed
    peaks = [df.loc[f"dithered__damped[viscous={b}]__s0", "peak_error_rad"] for b in ("0", "200")]
    assert peaks[0] != peaks[1]
    (d / "out" / "report.html").unlink()
    report = _cli("report", d / "out", cwd=d)
    assert report.returncode == 0, report.stderr
    assert "damped" in (d / "out" / "report.html").read_text(encoding="utf-8")


def test_example_step_against_solve_ivp(example_dir):
    """One interval of the example's step under a held torque from rest, against solve_ivp:
    stuck until x3 = ks at t_b = −τ3·ln(1 − ks/u), then J·ẋ2 = x3 − kc − b·x2, τ3·ẋ3 = u − x3.
    The semi-implicit sub-steps are first order (h = τs/200 = 50 µs): x2 within 2 %, x1 within 3 %
    (the breakaway falls on a sub-step boundary: up to h late); x3 and ∫|x3| are exact or
    trapezoidal."""
    sys.path.insert(0, str(example_dir))
    try:
        import viscous_plant
    finally:
        sys.path.remove(str(example_dir))
    from plant import DriveCommand, DriveType, SimOptions, initial_state
    p = viscous_plant.ViscousParams(viscous=300.0, command_velocity_initial=0.0)
    u = 6.0
    step = viscous_plant.Viscous().step(initial_state(p, x5=0.0), DriveCommand.hold(u, DriveType.LINEAR), p, None,
                                        SimOptions(noise=False))
    J, ks, kc, b, t3, ts = p.inertia, p.stiction, p.coulomb, p.viscous, p.motor_time_constant, p.sample_period
    t_b = -t3 * math.log(1.0 - ks / u)

    def rhs(t, z):
        x1, x2, x3 = z
        return [x2, (x3 - kc - b * x2) / J, (u - x3) / t3]

    ref = solve_ivp(rhs, (t_b, ts), [0.0, 0.0, ks], rtol=1e-12, atol=1e-18, method="Radau")
    assert step.state.mode == 3 and step.n_breakaways == 1
    assert step.state.x[1] == pytest.approx(ref.y[1, -1], rel=2e-2)
    assert step.state.x[0] == pytest.approx(ref.y[0, -1], rel=3e-2)
    assert step.state.x[2] == pytest.approx(u * (1 - math.exp(-ts / t3)), rel=1e-12)
    assert step.int_abs_current == pytest.approx(u * (ts - t3 * (1 - math.exp(-ts / t3))), rel=1e-5)
