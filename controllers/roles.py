"""The controllers the dissertation's claims are about, by role (the only place that says so).

``bench/`` and ``reports/`` never name a controller: the claims scorecard reads the *families*
below (results column ``controller_family``) and the speed comparison records the command
sequences of the registered controllers below. Change them here, or per run in
``config.json`` (``report.selection``) for the claims.
"""

from __future__ import annotations

__all__ = ["IDENTIFICATION", "CLASSICAL", "ADAPTIVE_PULSE"]

#: Acker's identification-and-control controller: the subject of the claims; its pulse
#: sequence is the speed comparison's workload.
IDENTIFICATION = "solnic"

#: The lag-compensated linear controller the claims compare against (2-6); its held levels are
#: the speed comparison's second sequence.
CLASSICAL = "linear"

#: Today's model-free adaptive pulse-width peer (Yang & Tomizuka 1988), which beats solnic on
#: thesis (docs/results.md); the robustness claims test that on every real plant.
ADAPTIVE_PULSE = "pulse-width"
