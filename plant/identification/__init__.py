"""Identification of a real axis from one experiment (SPEC §11 "The log of a real axis").

* :mod:`plant.identification.log` — the log format (CSV or Parquet: ``t``, ``u``, ``y`` and a
  header naming the drive and τs), read with one-line errors naming row and column;
* :mod:`plant.identification.experiment` — the excitation plan a user plays on the axis;
* :mod:`plant.identification.simulate` — a log simulated from any family (tests, examples);
* :mod:`plant.identification.fit` — the family's parameters from a log (weighted least squares
  on the noise-free simulated response, parametric bootstrap; ``auto``: held-out error over moves).
"""

import importlib

# Names load on first use, so reading the log format or the plan does not import scipy (CLI start-up).
_HOME = {"ExperimentOptions": "experiment", "design_experiment": "experiment",
         "FAMILY_FREE": "families", "AxisFit": "fit", "fit_log": "fit", "choose_family": "fit",
         "AxisLog": "log", "LogError": "log", "read_log": "log", "write_log": "log",
         "simulate_log": "simulate"}

__all__ = ["AxisLog", "LogError", "read_log", "write_log", "ExperimentOptions", "design_experiment",
           "simulate_log", "fit_log", "choose_family", "AxisFit", "FAMILY_FREE"]


def __getattr__(name: str) -> object:
    if name not in _HOME:
        raise AttributeError(f"module 'plant.identification' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"plant.identification.{_HOME[name]}"), name)
    globals()[name] = value
    return value
