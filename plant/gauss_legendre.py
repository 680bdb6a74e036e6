"""Gauss–Legendre nodes and weights on [−1, 1] as literal constants (4, 8 and 12 points).

Why constants: ``numpy.polynomial.legendre.leggauss`` finds the nodes as eigenvalues of the
Jacobi matrix with LAPACK (``eigvalsh``), whose kernel OpenBLAS picks by CPU; a node that
differed in its last bit on another machine would change every Q(h) built from it, and
stick-slip amplifies that (docs/results.md, "Reproducibility across machines"). These are the
doubles ``leggauss`` returns on this project's reference machine (numpy 2.4.6, OpenBLAS
0.3.31 Haswell and SkylakeX kernels alike), so every row computed with them is unchanged; the
nodes are the zeros of P_n within 4 ulps and the weights 2/((1 − x²)·P_n'(x)²) within 1e-14
relative (up to 58 ulps; checked against mpmath at 40 digits, tests/test_gauss_legendre.py), and
an n-point rule integrates x^k, k ≤ 2n − 1, to 4e-15.

Used by plant.multimode.moving (4 points), plant.multimode.transition and plant.two_mass.motion
(8 points), and solnic's noise model (12 points).
"""

from __future__ import annotations

import numpy as np

__all__ = ["nodes_weights"]

_RULES = {
    4: ((-0.8611363115940526, -0.33998104358485626, 0.33998104358485626, 0.8611363115940526),
        (0.34785484513745357, 0.6521451548625464, 0.6521451548625464, 0.34785484513745357)),
    8: ((-0.9602898564975362, -0.7966664774136267, -0.525532409916329, -0.18343464249564978,
         0.18343464249564978, 0.525532409916329, 0.7966664774136267, 0.9602898564975362),
        (0.10122853629037706, 0.22238103445337443, 0.3137066458778869, 0.36268378337836166,
         0.36268378337836166, 0.3137066458778869, 0.22238103445337443, 0.10122853629037706)),
    12: ((-0.9815606342467192, -0.9041172563704748, -0.7699026741943047, -0.5873179542866175,
          -0.3678314989981802, -0.1252334085114689, 0.1252334085114689, 0.3678314989981802,
          0.5873179542866175, 0.7699026741943047, 0.9041172563704748, 0.9815606342467192),
         (0.04717533638651141, 0.10693932599531907, 0.16007832854334642, 0.20316742672306573,
          0.2334925365383546, 0.2491470458134027, 0.2491470458134027, 0.2334925365383546,
          0.20316742672306573, 0.16007832854334642, 0.10693932599531907, 0.04717533638651141)),
}


def nodes_weights(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(nodes ascending, weights) of the n-point Gauss–Legendre rule on [−1, 1], n in 4, 8, 12
    (new arrays: the caller may keep them)."""
    if n not in _RULES:
        raise ValueError(f"Gauss-Legendre rule with {n} points is not tabulated (4, 8 or 12)")
    x, w = _RULES[n]
    return np.array(x), np.array(w)
