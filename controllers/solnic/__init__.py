"""The solnic controller (Acker 1967, ch. 5–7), split by idea.

* :mod:`~controllers.solnic.predictor` — the internal plant model, Δc_p, t_nominal, quasipartials;
* :mod:`~controllers.solnic.mode2_filter` — Kalman filter on (x1, x4) while stuck;
* :mod:`~controllers.solnic.friction_filter` — modified Kalman filter on (k̂c, k̂s);
* :mod:`~controllers.solnic.cost` — the cycle cost (6-1)–(6-5) and the a_c calibration;
* :mod:`~controllers.solnic.strategy` — sizes, the optimiser (6-9), (6-10), the trigger;
* :mod:`~controllers.solnic.options` — :class:`SolnicOptions`, presets and the a_c knob;
* :mod:`~controllers.solnic.controller` — :class:`SolnicController`, registered as ``"solnic"``;
* :mod:`~controllers.solnic.noise_model` — Δc bias and variance from the friction noise w2;
* :mod:`~controllers.solnic.braking` — the braking pulse pair, its timing and closed-form response;
* :mod:`~controllers.solnic.modern` — ``"solnic-modern"``, the same structure with the flags that measured best.
"""

from controllers.solnic.controller import SolnicController
from controllers.solnic.modern import SolnicModernController
from controllers.solnic.options import PRESETS, SolnicOptions

__all__ = ["SolnicController", "SolnicModernController", "SolnicOptions", "PRESETS"]
