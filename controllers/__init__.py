"""Pluggable controllers, registered by name (see :mod:`controllers.base`).

Built in: ``linear`` (lag-compensated, Bohacek–Tuteur limit), ``dithered`` (the same plus
square-wave dither) and ``solnic`` (Acker's semi-open-loop identification and control); today's
peers ``pulse-width`` (Yang & Tomizuka 1988), ``reset-pid`` (Beerens et al. 2019) and
``observer-pid`` (disturbance observer and adaptive Coulomb estimate, Friedland & Park 1992);
the deployed baseline ``friction-ff-pid`` (PID + static friction feedforward from the told model).
"""

from pathlib import Path as _Path

from plant import _jit_cache

_jit_cache.refresh(_Path(__file__).resolve().parent)   # compiled steps call helpers across files

from controllers.base import Controller, available_controllers, get_controller, make_controller, register

from controllers import linear as _linear  # noqa: E402,F401  (registers "linear")
from controllers import dithered as _dithered  # noqa: E402,F401  (registers "dithered")
from controllers import solnic as _solnic  # noqa: E402,F401  (registers "solnic")
from controllers import pulse_width as _pulse_width  # noqa: E402,F401  (registers "pulse-width")
from controllers import reset_pid as _reset_pid  # noqa: E402,F401  (registers "reset-pid")
from controllers import observer_pid as _observer_pid  # noqa: E402,F401  (registers "observer-pid")
from controllers import friction_ff_pid as _friction_ff_pid  # noqa: E402,F401  (registers "friction-ff-pid")
from controllers import oracle_pulse as _oracle_pulse  # noqa: E402,F401  (registers the "oracle-pulse" bound)

__all__ = ["Controller", "register", "get_controller", "available_controllers", "make_controller"]
