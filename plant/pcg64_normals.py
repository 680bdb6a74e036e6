"""numpy's standard normals from a PCG64 state, compiled inline: the same numbers, cheaper.

``numpy.random.Generator(PCG64).standard_normal`` draws each unit normal with the ziggurat of
numpy's ``random_standard_normal`` (256 layers; Marsaglia & Tsang 2000), which asks the bit
generator for 64-bit words through a function pointer, one call per word. :func:`fill_normals`
runs the same ziggurat with the same tables (numba's copies of numpy's ``ki_double``,
``wi_double``, ``fi_double``) on PCG64's 128-bit LCG step written out in LLVM IR, so nothing is
called per word:

    s ← s·M + inc  (mod 2¹²⁸),    word = rotr64(hi(s) ⊕ lo(s), hi(s) >> 58)      (PCG XSL-RR)

and a uniform double is (word >> 11)·2⁻⁵³, as numpy's ``pcg64_next_double``. The layer test,
the tail (log1p) and the wedge (exp) are numpy's expressions in numpy's order, calling the
same libm. The state is read from and written back to the Generator's ``bit_generator.state``
around each fill (:func:`draw_into`), so the generator is where numpy would have left it.
tests/test_pcg64_normals.py compares draws and the state after, bit for bit, with numpy.
"""

from __future__ import annotations

import math

import llvmlite.ir as ir
import numpy as np
from numba import njit, types
from numba.extending import intrinsic

try:    # numba's copies of numpy's ziggurat tables (a private module: without it, numpy draws)
    from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r
    _TABLES = True
except ImportError:     # pragma: no cover - depends on the numba version
    fi_double = ki_double = wi_double = np.zeros(256)
    ziggurat_nor_inv_r = ziggurat_nor_r = 1.0
    _TABLES = False

__all__ = ["fill_normals", "draw_into", "applies"]

_MULT = (2549297995355413924 << 64) + 4865540595714422341     # PCG_DEFAULT_MULTIPLIER_128
_MASK64 = (1 << 64) - 1
_KI = np.asarray(ki_double, dtype=np.uint64)
_WI = np.asarray(wi_double, dtype=np.float64)
_FI = np.asarray(fi_double, dtype=np.float64)
_NOR_R = float(ziggurat_nor_r)
_NOR_INV_R = float(ziggurat_nor_inv_r)
_TABLES = _TABLES and _KI.shape == _WI.shape == _FI.shape == (256,)
_TWO_M53 = 1.0 / 9007199254740992.0


@intrinsic
def _pcg_next(typingctx, st):
    """One PCG64 step on ``st`` = [state hi, state lo, inc hi, inc lo] (uint64[4], updated in
    place); returns the XSL-RR output word of the new state."""
    if not (isinstance(st, types.Array) and st.dtype == types.uint64 and st.ndim == 1 and st.layout == "C"):
        return None
    sig = types.uint64(st)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = ary.data
        i64, i128 = ir.IntType(64), ir.IntType(128)
        vals = [builder.load(builder.gep(ptr, [ir.Constant(ir.IntType(64), k)])) for k in range(4)]
        shift = ir.Constant(i128, 64)

        def join(hi, lo):
            return builder.or_(builder.shl(builder.zext(hi, i128), shift), builder.zext(lo, i128))

        s = join(vals[0], vals[1])
        inc = join(vals[2], vals[3])
        s = builder.add(builder.mul(s, ir.Constant(i128, _MULT)), inc)
        hi = builder.trunc(builder.lshr(s, shift), i64)
        lo = builder.trunc(s, i64)
        builder.store(hi, builder.gep(ptr, [ir.Constant(ir.IntType(64), 0)]))
        builder.store(lo, builder.gep(ptr, [ir.Constant(ir.IntType(64), 1)]))
        rot = builder.lshr(hi, ir.Constant(i64, 58))
        x = builder.xor(hi, lo)
        fshr = builder.module.declare_intrinsic("llvm.fshr", [i64], ir.FunctionType(i64, [i64, i64, i64]))
        return builder.call(fshr, [x, x, rot])        # rotr64(x, rot)

    return sig, codegen


@njit(cache=True, inline="always")
def _next_double(st):
    """numpy's pcg64_next_double: (word >> 11)·2⁻⁵³."""
    return float(_pcg_next(st) >> np.uint64(11)) * _TWO_M53


@njit(cache=True, _nrt=False)
def fill_normals(st, out):
    """out[:] = the next out.shape[0] standard normals of numpy's Generator(PCG64) with state
    ``st`` (uint64[4]: state hi, lo, inc hi, lo; advanced in place): ``random_standard_normal``'s
    ziggurat, step for step."""
    m8 = np.uint64(0xff)
    one = np.uint64(1)
    m52 = np.uint64(0x000fffffffffffff)
    for n in range(out.shape[0]):
        while True:
            r = _pcg_next(st)
            idx = np.intp(r & m8)
            r = r >> np.uint64(8)
            sign = r & one
            rabs = (r >> one) & m52
            x = float(rabs) * _WI[idx]
            if sign == one:
                x = -x
            if rabs < _KI[idx]:
                break                                   # 99.3 % of the draws
            if idx == 0:
                while True:
                    xx = -_NOR_INV_R * math.log1p(-_next_double(st))
                    yy = -math.log1p(-_next_double(st))
                    if yy + yy > xx * xx:
                        if ((rabs >> np.uint64(8)) & one) == one:
                            x = -(_NOR_R + xx)
                        else:
                            x = _NOR_R + xx
                        break
                break
            if (_FI[idx - 1] - _FI[idx]) * _next_double(st) + _FI[idx] < math.exp(-0.5 * x * x):
                break
        out[n] = x


def applies(rng: np.random.Generator) -> bool:
    """True when ``rng``'s bit generator is exactly numpy's PCG64 (the stream fill_normals reproduces)
    and numba's copies of the ziggurat tables are available."""
    return _TABLES and type(rng.bit_generator) is np.random.PCG64


def draw_into(rng: np.random.Generator, out: np.ndarray) -> None:
    """``rng.standard_normal(out=out)`` for a PCG64 generator (:func:`applies`), via :func:`fill_normals`:
    the same numbers, and the generator's state afterwards is the one numpy leaves."""
    bg = rng.bit_generator
    with bg.lock:                   # as numpy's own draws hold it
        full = bg.state
        pcg = full["state"]
        s, inc = pcg["state"], pcg["inc"]
        st = np.array([s >> 64, s & _MASK64, inc >> 64, inc & _MASK64], dtype=np.uint64)
        fill_normals(st, out)
        pcg["state"] = (int(st[0]) << 64) | int(st[1])
        bg.state = full
