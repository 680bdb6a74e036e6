"""The Gymnasium environment (bench/gym_env.py) and the policy adapter (controllers/policy.py).

Independent truth here is the bench runner itself: the environment must step the plant a matrix
cell steps (same seed → same noise, same truth at every instant), and a policy that *is* a
registered controller must give that controller's results row bit for bit (the runner runs
``linear`` in its compiled loop, the adapter through ``step``: two different code paths).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pandas as pd
import pytest
from gymnasium.utils.env_checker import check_env

from bench.cells import RUNTIME_COLUMNS, Cell, ControllerSpec, run_cell
from bench.gym_env import ENV_ID, StickSlipEnv
from bench.runner import run_closed_loop, spawn_streams
from bench.scenarios import builtin_scenarios
from controllers.base import make_controller
from controllers.policy import command_of, policy_controller, register_policy
from plant.drive import DriveType
from plant.protocol import get_family

ROOT = Path(__file__).resolve().parent.parent
# One built-in scenario of each plant family (asserted below, so a renamed scenario fails loudly).
FAMILY_SCENARIOS = {"multimode": "thesis", "two-mass": "compliant", "stribeck": "stribeck", "lugre": "lugre"}


class ControllerPolicy:
    """A registered controller seen as a policy: the last observed sample in, its level out."""

    def __init__(self, name: str = "linear") -> None:
        self.controller = make_controller(name)

    def reset(self, params, rng) -> None:
        self.controller.reset(params, rng)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        command = self.controller.step(float(obs[-1]))
        (offset, level), = command.segments
        assert offset == 0.0
        return np.array([level])

    def summary(self):
        return self.controller.summary()


@pytest.mark.parametrize("family,drive", [(f, DriveType.LINEAR.value) for f in FAMILY_SCENARIOS]
                         + [("multimode", DriveType.BRIDGE.value)])
def test_check_env_passes_for_every_family(family, drive):
    scenario = FAMILY_SCENARIOS[family]
    assert builtin_scenarios()[scenario].family == family
    env = gymnasium.make(ENV_ID, scenario=scenario, drive=drive, window=3, max_steps=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the advice on unbounded / unnormalised Boxes
        check_env(env.unwrapped)
    assert env.unwrapped.family is get_family(family)


def test_module_prefixed_id_imports_the_env():
    env = gymnasium.make(f"bench.gym_env:{ENV_ID}", scenario="thesis", max_steps=5)
    assert isinstance(env.unwrapped, StickSlipEnv)


def _episode(seed, actions, **kw):
    env = StickSlipEnv(**kw)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, *_ = env.step(a)
        out.append(obs)
    return np.array(out)


@pytest.mark.parametrize("scenario,drive", [("delayed", "linear"), ("lugre", "bridge")])
def test_same_seed_and_actions_give_bit_identical_observations(scenario, drive):
    env = StickSlipEnv(scenario=scenario, drive=drive, window=4)
    env.action_space.seed(7)
    actions = [env.action_space.sample() * 0.05 for _ in range(40)]
    a = _episode(3, actions, scenario=scenario, drive=drive, window=4)
    b = _episode(3, actions, scenario=scenario, drive=drive, window=4)
    c = _episode(4, actions, scenario=scenario, drive=drive, window=4)
    assert a.shape == (41, 4)
    assert np.array_equal(a, b)                      # bit for bit
    assert not np.array_equal(a[1:], c[1:])          # and the seed matters (sensor noise differs)
    env.reset(seed=3)                                # a second reset of one env repeats the run
    again = [env.reset(seed=3)[0]] + [env.step(x)[0] for x in actions]
    assert np.array_equal(np.array(again), a)


@pytest.mark.parametrize("scenario", ["delayed", "quantized", "lugre", "compliant", "mismatch"])
def test_env_truth_per_step_equals_the_runner_on_the_same_seed(scenario):
    """The runner's recorded samples (linear controller, seed 5) vs the environment driven by
    the same controller's levels: y and every truth field equal at every instant."""
    seed, n = 5, 60
    sc = builtin_scenarios()[scenario]
    truth, _ = sc.realise(seed)
    ref = run_closed_loop(truth, make_controller("linear"), family=sc.family, model=sc.model_params(),
                          duration_s=n * truth.sample_period, seed=seed, record=True)
    assert ref.status == "ok"
    env = StickSlipEnv(scenario=scenario, max_steps=n)
    policy = ControllerPolicy()
    policy.reset(env.model, spawn_streams(seed)["controller"])
    obs, info = env.reset(seed=seed)
    rows, current = [info], 0.0
    for _ in range(n):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        rows.append(info)
        current += info["int_abs_current"]
    assert truncated and not terminated
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(policy(obs))
    for k, series in ref.samples.items():
        assert np.array_equal(np.array([r[k] for r in rows[:n]]), series), k
    # the scored sums agree too: Σ∫|x3|dt over the episode / T is the runner's mean_abs_current
    assert current / (n * truth.sample_period) == pytest.approx(ref.metrics["mean_abs_current"], rel=1e-12)


def test_reward_is_the_weighted_error_and_current():
    env = StickSlipEnv(scenario="thesis", error_weight=2.0, current_weight=0.5, max_steps=5)
    env.reset(seed=1)
    _, reward, _, _, info = env.step(np.array([3.0]))
    tau = env.scenario.params.sample_period
    assert reward == pytest.approx(-(2.0 * abs(info["x1"]) + 0.5 * info["int_abs_current"] / tau), rel=1e-12)
    assert info["int_abs_current"] > 0


def test_bridge_pulse_width_sets_the_charge():
    """From rest without noise, a wider pulse draws more ∫|x3| dt; width 0 draws none; a width
    beyond τs is the whole interval; the sign is the direction of the current."""
    charges = {}
    for w in (0.0, 1e-3, 4e-3, 0.01, 0.5, -4e-3):
        env = StickSlipEnv(scenario="thesis", drive="bridge", noise=False, max_steps=1)
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.array([w]))
        charges[w] = (info["int_abs_current"], info["x3"])
    assert charges[0.0][0] == 0.0
    assert 0 < charges[1e-3][0] < charges[4e-3][0] < charges[0.01][0] == charges[0.5][0]
    assert charges[-4e-3][0] == pytest.approx(charges[4e-3][0], rel=1e-12)
    assert charges[0.01][1] > 0 > command_of(np.array([-0.01]), DriveType.BRIDGE, env.scenario.params).segments[0][1]


def test_scenario_of_a_matrix_file(tmp_path):
    (tmp_path / "m.toml").write_text('[matrix]\ncontrollers = ["linear"]\nscenarios = ["heavy"]\nseeds = [0]\n'
                                     'duration_s = 0.5\nwarmup_s = 0.1\n\n[scenarios.heavy]\nbase = "lugre"\ninertia = 1.5\n')
    env = StickSlipEnv(scenario="heavy", matrix=tmp_path / "m.toml")
    assert env.scenario.family == "lugre" and env.scenario.params.inertia == 1.5
    assert env.max_steps == 50                                      # the matrix's duration_s / τs
    with pytest.raises(ValueError, match="scenario: unknown 'thesis'"):
        StickSlipEnv(scenario="thesis", matrix=tmp_path / "m.toml")


def test_a_runaway_terminates_the_episode():
    """Full-width pulses one way from rest: the shaft runs off (|x1| beyond SimOptions.diverge_error,
    1 rad) and the episode terminates with the plant's status; stepping on is refused."""
    env = StickSlipEnv(scenario="thesis", drive="bridge", noise=False, max_steps=2000)
    env.reset(seed=0)
    for n in range(2000):
        _, _, terminated, truncated, info = env.step(np.array([0.01]))
        if terminated or truncated:
            break
    assert terminated and not truncated and n < 100
    assert info["status"] == "diverged" and abs(info["x1"]) > 1.0
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.array([0.0]))


@pytest.mark.parametrize("kw,field", [({"drive": "pwm"}, "drive"), ({"window": 0}, "window"),
                                      ({"error_weight": -1.0}, "error_weight"), ({"max_steps": 0}, "max_steps"),
                                      ({"scenario": "nope"}, "scenario")])
def test_bad_options_name_the_field(kw, field):
    with pytest.raises(ValueError, match=field):
        StickSlipEnv(**kw)


@pytest.fixture(scope="module")
def registered_linear_policy():
    return register_policy("linear-as-policy", ControllerPolicy, drive="linear", window=2)


@pytest.mark.parametrize("scenario", ["thesis", "delayed", "stribeck"])
def test_policy_adapter_reproduces_the_registered_controller_row(registered_linear_policy, scenario, tmp_path):
    sc = builtin_scenarios()[scenario].with_durations(2.0, 0.5)
    rows = [run_cell(Cell(ControllerSpec(name, name), sc, 3), tmp_path, traces=False)
            for name in ("linear", "linear-as-policy")]
    assert rows[0]["status"] == rows[1]["status"] == "ok"
    assert rows[1]["controller_family"] == "policy"
    different = {"cell", "controller", "controller_base", "controller_family", "config_hash", "definition_hash",
                 *RUNTIME_COLUMNS}
    assert set(rows[0]) == set(rows[1])
    for col in sorted(set(rows[0]) - different):
        a, b = rows[0][col], rows[1][col]
        assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), col


def test_direct_policy_controller_matches_run_closed_loop():
    sc = builtin_scenarios()["quantized"]
    kw = dict(family=sc.family, duration_s=1.0, seed=2)
    a = run_closed_loop(sc.params, make_controller("linear"), **kw)
    b = run_closed_loop(sc.params, policy_controller(ControllerPolicy()), **kw)
    assert {k: v for k, v in a.metrics.items() if k not in RUNTIME_COLUMNS} == \
        {k: v for k, v in b.metrics.items() if k not in RUNTIME_COLUMNS}


def test_policy_options_and_actions_are_checked(registered_linear_policy):
    with pytest.raises(ValueError, match="window"):
        registered_linear_policy(window=0)
    assert registered_linear_policy().options.window == 2 and registered_linear_policy(window=5).options.window == 5
    p = dataclasses.replace(builtin_scenarios()["thesis"].params)
    with pytest.raises(ValueError, match="one finite number"):
        command_of(np.array([math.nan]), DriveType.LINEAR, p)
    with pytest.raises(ValueError, match="bridge command for a linear drive"):
        command_of(command_of(np.array([1e-3]), DriveType.BRIDGE, p), DriveType.LINEAR, p)


def _doc_example(name: str) -> str:
    text = (ROOT / "docs" / "gym.md").read_text(encoding="utf-8")
    m = re.search(rf"<!-- example: {re.escape(name)} -->\n```\w+\n(.*?)\n```", text, re.S)
    assert m, f"docs/gym.md has no example block {name!r}"
    return m.group(1) + "\n"


@pytest.mark.slow
def test_docs_example_runs_in_the_env_and_through_the_matrix(tmp_path):
    """docs/gym.md's scripted policy, exactly as printed: its episode in the environment, then
    the matrix through the real CLI (twice: the second run resumes every cell)."""
    for name in ("scripted_policy.py", "policy.toml"):
        (tmp_path / name).write_text(_doc_example(name))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    episode = subprocess.run([sys.executable, "scripted_policy.py"], cwd=tmp_path, env=env, capture_output=True,
                             text=True, timeout=300)
    assert episode.returncode == 0, episode.stderr
    returns = dict(re.findall(r"^(\w+): return (\S+) over", episode.stdout, re.M))
    assert returns["scripted"] == "-140.2"                      # the number docs/gym.md states
    assert float(returns["random"]) < 1e3 * float(returns["scripted"])
    for attempt in range(2):
        proc = subprocess.run([sys.executable, "-m", "reports.cli", "run", "--matrix", "policy.toml", "--out", "run",
                               "--no-traces"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
    assert "0 computed, 6 resumed" in proc.stdout
    df = pd.read_parquet(tmp_path / "run" / "results.parquet").set_index("cell")
    assert (df["status"] == "ok").all(), df["message"]
    policy_rows = df[df["controller"].str.startswith("scripted-pulse")]
    assert len(policy_rows) == 4 and (policy_rows["controller_family"] == "policy").all()
    assert (policy_rows["rms_error_rad"] > 0).all()
