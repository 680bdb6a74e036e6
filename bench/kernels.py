"""Which numeric kernels this process computes with: one string per process, stored in every row.

A cell's rows are bit-identical on every executor of one machine, and under both OpenBLAS
kernels tried (Haswell, SkylakeX) on all 11 built-in scenarios: the plants and the controllers'
designs compute without BLAS or LAPACK (plant.fixed_linalg, plant.two_mass.eigen,
plant.gauss_legendre, controllers.discrete_tf). What still depends on the CPU: numpy's
element-wise functions (``exp``, ``log``, ``power``) pick SIMD loops by CPU, and glibc's libm
picks FMA or non-FMA variants of ``exp``, ``pow``, ``sin``, ``erfc``, ... by CPU; each rounds in
its own way, and stick-slip amplifies last-bit differences (measured: docs/results.md,
"Reproducibility across machines"). So each row says which BLAS kernels and SIMD level made it,
and ``run`` and the report say when one results directory mixes rows of several.

The string is read with threadpoolctl (the BLAS libraries loaded in this process: numpy's and
scipy's OpenBLAS, the latter being numba's BLAS) and numpy's CPU dispatch table, e.g.
``"numpy openblas 0.3.31.188.0 Haswell; scipy openblas 0.3.30 Haswell; simd AVX512_ICL"``.
"""

from __future__ import annotations

from functools import lru_cache

__all__ = ["numeric_kernel", "mixed_kernels_note", "KERNEL_COLUMN"]

KERNEL_COLUMN = "numeric_kernel"


def _owner(filepath: str) -> str:
    """``numpy`` or ``scipy`` for a library shipped in ``numpy.libs``/``scipy.libs`` (wheels), else
    the library file's name."""
    parts = filepath.replace("\\", "/").split("/")
    for part in reversed(parts[:-1]):
        if part.endswith(".libs"):
            return part[: -len(".libs")]
    return parts[-1]


def _simd() -> str:
    """The highest CPU feature numpy dispatches to here (``AVX512_ICL``, ``X86_V3``, ...)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:   # numpy < 2
        try:
            from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
        except ImportError:
            return "unknown"
    found = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    return found[-1] if found else "baseline"


@lru_cache(maxsize=1)
def numeric_kernel() -> str:
    """The BLAS libraries (owner, implementation, version, kernel architecture) and numpy's SIMD
    level of this process, as one line. scipy.linalg is imported first so that its BLAS, numba's,
    is loaded and listed."""
    import scipy.linalg  # noqa: F401 — loads scipy's BLAS, the one numba's np.dot and @ call
    from threadpoolctl import threadpool_info

    libs = sorted({(_owner(i.get("filepath", "")), i.get("internal_api", "?"), str(i.get("version") or "?"),
                    str(i.get("architecture") or "?"))
                   for i in threadpool_info() if i.get("user_api") == "blas"})
    parts = [" ".join(lib) for lib in libs]
    return "; ".join([*parts, f"simd {_simd()}"])


def mixed_kernels_note(results) -> str | None:
    """One line when the rows of ``results`` (a DataFrame of cell rows) were computed under more than
    one numeric kernel, naming each with its row count; None otherwise (rows without the column —
    failures, older stores — are not counted)."""
    if KERNEL_COLUMN not in getattr(results, "columns", ()):
        return None
    kernels = results[KERNEL_COLUMN].dropna().astype(str)
    counts = kernels[kernels != ""].value_counts()
    if len(counts) < 2:
        return None
    each = "; ".join(f"[{k}]: {n} rows" for k, n in counts.sort_index().items())
    return (f"these rows were computed under {len(counts)} numeric kernels ({each}): a cell computed under two "
            "of them may differ in its last bits and, through stick-slip, in its metrics (docs/results.md, "
            "\"Reproducibility across machines\")")
