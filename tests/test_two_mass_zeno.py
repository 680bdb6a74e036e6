"""The two-mass kernel at k̄s = k̄c (issue 25, tenth session): a breakaway leaves the load at
x2 = 0 with ẋ2 = (T − kc)/J = 0, and the kernel must let it slide off (ẍ2 = Ṫ/J > 0) as the
physics does, not stop it at once on a rounding-level slope and reflect it at one instant
until the event cap (status chatter: seed 6571 two-mass case 8's point fit, docs/axis.md
"Tenth session"). Truth: tests/two_mass_reference.py (solve_ivp, DOP853, with events),
written from the equations, not from plant.two_mass."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from two_mass_reference import reference_interval  # noqa: E402

from plant.drive import DriveCommand, DriveType  # noqa: E402
from plant.protocol import get_family  # noqa: E402
from plant.state import SimOptions, Status  # noqa: E402
from plant.two_mass.interval import _x1_peak, plan, root_steps  # noqa: E402
from plant.two_mass.motion import A1, A3, AKC, NX, PHI, WM  # noqa: E402

FAM = get_family("two-mass")
# the point of seed 6571 two-mass case 8's point fit that chattered (k̄s = k̄c, x4 off as in the fit)
ZENO = FAM.Params().replace(inertia=0.8793840585261529, motor_time_constant=0.0037404330173091676,
                            coulomb=0.5881306837875517, stiction=0.5881306837875517, shaft_stiffness=5000.0,
                            shaft_damping=2.5, motor_inertia=0.05, u_max=20.0, sample_period=0.01,
                            command_velocity_std=0.0, command_velocity_initial=0.0)


@pytest.mark.parametrize("k_sh", [5000.0, 40000.0])
@pytest.mark.parametrize("width", [0.0012, 0.0016])
@pytest.mark.parametrize("eps", [0.0, 1e-15, 1e-12, 1e-9, 1e-3])
def test_full_torque_pulse_at_equal_levels_matches_the_reference(k_sh, width, eps):
    """A full-torque pulse from rest, k̄s = k̄c·(1 + ε): the interval ends ok, its state within
    1e-12 (relative) of solve_ivp's, one breakaway and no stop (the reference's events). Before
    the fix, ε = 0 ended in status chatter after 2001 events at t ≈ 1.6 ms."""
    p = ZENO.replace(shaft_stiffness=k_sh, stiction=ZENO.coulomb * (1.0 + eps))
    cmd = DriveCommand(((0.0, 20.0), (width, 0.0)), DriveType.LINEAR)
    r0 = root_steps()
    st = FAM.step(FAM.initial_state(p, 0.0), cmd, p, None, SimOptions(noise=False))
    roots = root_steps() - r0
    y, mode, _, events = reference_interval(p, [0, 0, 0, 0, 0, 0], 2, False, [(0.0, 20.0), (width, 0.0)], False,
                                            p.sample_period)
    assert [kind for _, kind in events] == ["breakaway"]
    assert st.status is Status.OK and st.state.mode == mode == 3
    x = st.state.x
    for got, want in ((x[0], y[0]), (x[1], y[1]), (x[2], y[2]), (x[6], y[4]), (x[7], y[5])):
        assert abs(got - want) <= 1e-12 * abs(want), (got, want)
    # mode 3 throughout after the breakaway (no velocity zero): x1 rises monotonically, the peak is the end
    assert abs(st.peak_abs_error - abs(y[0])) <= 1e-12 * abs(y[0])
    assert roots < 2000, roots         # was ~4·10⁷ (2001 events × 2·10⁴) at ε = 0


def test_x1_peak_of_an_empty_segment_returns_at_once():
    """_x1_peak over τ = 0 (a velocity zero at the segment's start): the start's |x1| and no
    work. It used to go round its loop 10000 times on zero-length steps (20000 counted steps)."""
    p = ZENO
    q, V, Vi, lam = plan(p, SimOptions(noise=False))[:4]
    X = np.zeros(NX)
    # the chattering state: load at rest in mode 3, shaft torque at k̄s to rounding, falling
    X[A3], X[AKC], X[PHI], X[WM] = 4.9108058916003605, p.coulomb, 6.4275091306839507e-05, 1.0670209090134175e-01
    X[A1] = 3.0e-6
    peak, work = _x1_peak(X, 3, 0.0, p.kernel_record()[0], q, V, Vi, lam, 3.0e-6, np.empty(NX))
    assert peak == 3.0e-6 and work == 0
