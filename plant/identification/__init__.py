"""Identification of a real axis from one experiment (SPEC §11 "The log of a real axis").

* :mod:`plant.identification.log` — the log format (CSV or Parquet: ``t``, ``u``, ``y`` and a
  header naming the drive and τs), read with one-line errors naming row and column;
* :mod:`plant.identification.experiment` — the excitation plan a user plays on the axis;
* :mod:`plant.identification.simulate` — a log simulated from any family (tests, examples);
* :mod:`plant.identification.fit` — the family's parameters from a log (weighted least squares
  on the noise-free simulated response, cluster-robust Gauss–Newton covariance, BIC).
"""

from plant.identification.experiment import ExperimentOptions, design_experiment
from plant.identification.fit import FAMILY_FREE, AxisFit, fit_log, choose_family
from plant.identification.log import AxisLog, LogError, read_log, write_log
from plant.identification.simulate import simulate_log

__all__ = ["AxisLog", "LogError", "read_log", "write_log", "ExperimentOptions", "design_experiment",
           "simulate_log", "fit_log", "choose_family", "AxisFit", "FAMILY_FREE"]
