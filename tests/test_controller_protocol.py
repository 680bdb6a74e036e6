"""Controller protocol v2: typed options, presets, knobs, hooks, and that bench/ and reports/
name no controller."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from controllers.base import Controller, available_controllers, get_controller, register, resolve_options

ROOT = Path(__file__).resolve().parent.parent
REGISTERED = sorted(available_controllers())


@pytest.mark.parametrize("name", REGISTERED)
def test_options_presets_and_knobs_are_consistent(name):
    cls = get_controller(name)
    if cls.Options is None:
        pytest.skip(f"{name} has no Options dataclass yet")
    assert dataclasses.is_dataclass(cls.Options)
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(cls.Options(), dataclasses.fields(cls.Options)[0].name, None)
    for preset, options in cls.presets.items():
        assert isinstance(options, cls.Options), preset
        assert cls(preset=preset).options == options
    fields = {f.name for f in dataclasses.fields(cls.Options)}
    for knob, values in cls.knobs.items():
        assert knob in fields and len(values) >= 2
        for v in values:   # every documented sweep value is a valid option
            assert getattr(resolve_options(cls, None, None, {knob: v}), knob) == v


@pytest.mark.parametrize("name", REGISTERED)
def test_hooks_have_their_documented_types(name):
    from plant import PlantParams

    cls = get_controller(name)
    assert cls.family and isinstance(cls.counter, str)
    c = cls()
    p = PlantParams()
    c.reset(p, np.random.default_rng(0))
    for _ in range(3):
        if cls.privileged:
            from plant.protocol import TruePlant, get_family
            from plant.state import initial_state
            c.observe_truth(initial_state(p, x5=0.0), TruePlant(get_family("multimode"), p))
        c.step(0.0)
    if cls.counter:
        assert isinstance(c.summary()[cls.counter], int)
    for label, times in c.event_times().items():
        assert isinstance(label, str) and np.asarray(times).ndim == 1
    t = np.arange(3) * 0.01
    for key, values in c.report_series(t, 0.0).items():
        assert np.asarray(values).shape == t.shape, key


def test_variants_keep_the_family_and_subclasses_may_choose_their_own():
    assert get_controller("dithered").family == "dithered"
    assert get_controller("reset-pid").family == "reset-pid"

    @register("test-linear-variant-xyz")
    class _V(get_controller("linear")):
        pass

    try:
        assert _V.family == "linear"
    finally:
        from controllers.base import _REGISTRY
        _REGISTRY.pop("test-linear-variant-xyz")


@dataclasses.dataclass(frozen=True)
class _Opts:
    gain: float = 1.0
    steps: int = 3
    mode: str = "a"
    limit: float | None = None
    on: bool = True

    def __post_init__(self):
        if self.gain <= 0:
            raise ValueError(f"gain must be > 0, got {self.gain!r}")


class _Toy(Controller):
    name = "toy"
    Options = _Opts
    presets = {"big": _Opts(gain=10.0)}

    def reset(self, params, rng):
        pass

    def step(self, y):
        raise NotImplementedError


def test_resolve_options_defaults_presets_instances_and_overrides():
    assert _Toy().options == _Opts()
    assert _Toy(preset="big", steps=5).options == _Opts(gain=10.0, steps=5)
    assert _Toy(_Opts(mode="b"), gain=2).options == _Opts(gain=2.0, mode="b")
    assert isinstance(_Toy(gain=2).options.gain, float)          # int accepted for a float field
    assert _Toy(limit=None).options.limit is None and _Toy(limit=3).options.limit == 3.0


@pytest.mark.parametrize("kwargs, match", [
    ({"gian": 1.0}, "unknown option 'gian' of 'toy'"),
    ({"gain": "x"}, "option 'gain' of 'toy' must be a number, got 'x'"),
    ({"gain": True}, "option 'gain' of 'toy' must be a number"),
    ({"steps": 2.5}, "option 'steps' of 'toy' must be an integer"),
    ({"on": 1}, "option 'on' of 'toy' must be true or false"),
    ({"mode": 3}, "option 'mode' of 'toy' must be a string"),
    ({"limit": "high"}, "option 'limit' of 'toy' must be a number"),
    ({"gain": -1.0}, "gain must be > 0"),
    ({"preset": "small"}, "unknown preset 'small' of 'toy'"),
])
def test_resolve_options_errors_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=re.escape(match)):
        _Toy(**kwargs)


def test_options_object_and_preset_exclude_each_other():
    with pytest.raises(ValueError, match="not both"):
        _Toy(_Opts(), preset="big")
    with pytest.raises(ValueError, match="must be a _Opts"):
        _Toy({"gain": 1.0})


def test_privileged_hook_is_refused_by_real_controllers():
    with pytest.raises(NotImplementedError, match="not privileged"):
        get_controller("linear")().observe_truth(None, None)


def test_bench_and_reports_name_no_controller():
    """Registered names may appear only in docstrings/comments' examples, never in code."""
    names = [n for n in REGISTERED]
    pattern = re.compile(r"""["'](%s)["']""" % "|".join(map(re.escape, names)))
    offenders = []
    for folder in ("bench", "reports"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            code = re.sub(r'"""[\s\S]*?"""', "", text)   # drop docstrings
            code = "\n".join(line.split("#", 1)[0] for line in code.splitlines())
            for m in pattern.finditer(code):
                offenders.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert not offenders, offenders


def test_controllers_do_not_import_bench():
    for path in sorted((ROOT / "controllers").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"^\s*(from|import) bench\b", text, re.M), path


def test_phase_peaks_assign_every_point_to_the_phase_that_owns_it():
    from bench.runner import RunResult
    from bench.series import phase_peaks

    t = np.arange(10) * 0.1                               # samples 0.0 … 0.9 s
    x1 = np.array([9, 1, 2, 3, 4, 5, 6, 7, 8, 0.5]) * 1e-6
    ev = {"t": np.array([0.35, 0.55]), "x1": np.array([-9.5e-6, 20e-6])}
    res = RunResult("ok", "", {}, samples={"t": t, "x1": x1}, events=ev)
    # phase a owns [0.2, 0.5) and [0.8, end]; b owns [0.5, 0.8); warm-up 0.1 s drops t = 0.0
    peaks = phase_peaks(res, {"phase:a": [0.2, 0.8], "phase:b": [0.5], "pulse": [0.3]}, 0.1)
    assert peaks == {"peak_error_a_rad": 9.5e-6, "peak_error_b_rad": 20e-6}
    assert phase_peaks(res, {"pulse": [0.3]}, 0.0) == {}
