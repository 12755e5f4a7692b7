"""A scan of one circle or box against 8 slots per step, its hits compressed into the pair buffer.

Where pairs are many (a clustered scene makes millions a frame), the scalar branch-free scan is
bound by its instruction count: per test a store of the pair, the min and max that order it, and
the overlap test, 2.5 ns per test. This one tests 8 candidates with a few vector instructions and
packs the hits' pairs together with a vector compress (AVX-512's vpcompressq), then stores them
as one block whose rows past the hits are written again by the next block. On the clustered scene
at n = 131072 (7 million tests, 5.9 million pairs) an own.grid frame went from 18.8 to 11.5 ms
(`python -m studies.bench`, its scalar ms column), 1.9x the floor.

numba has no vector types, so the block is written in LLVM IR with generic intrinsics, which LLVM
lowers for any CPU. Without AVX-512 the compress becomes a loop through the stack, 3x slower than
the scalar scan: own.grid takes this path by default only where `NATIVE` says the CPU has it.
"""

from __future__ import annotations

import llvmlite.binding as llvm
import numba as nb
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

LANES = 8
# A block's store writes LANES // 2 rows at the pair count whatever its hits: the buffer needs
# this many rows past the last pair (callers check it with the rows of their tests).
SLACK_ROWS = LANES


def _compresses_natively() -> bool:
    """True where numba compiles for a CPU with AVX-512 (its vector compress is one instruction)."""
    if nb.config.CPU_NAME and nb.config.CPU_NAME != "host":
        features = nb.config.CPU_FEATURES or ""
    else:
        features = nb.config.CPU_FEATURES or llvm.get_host_cpu_features().flatten()
    return "+avx512f" in features.split(",")


NATIVE = _compresses_natively()

_I1, _I32, _I64, _F64 = ir.IntType(1), ir.IntType(32), ir.IntType(64), ir.DoubleType()


def _vec(t, k=LANES):
    return ir.VectorType(t, k)


def _intrinsic_fn(builder, name, ret, args):
    return cgutils.get_or_insert_function(builder.module, ir.FunctionType(ret, args), name)


def _splat(builder, value, t):
    undef = ir.Constant(_vec(t), ir.Undefined)
    one = builder.insert_element(undef, value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(one, undef, ir.Constant(_vec(_I32), [0] * LANES))


def _masked_load(builder, ptr, mask, t, k=LANES):
    """k elements of type t from ptr where mask is set (the others are not read: no fault past
    the end of an array)."""
    fn = _intrinsic_fn(builder, f"llvm.masked.load.v{k}{'f64' if t is _F64 else 'i64'}", _vec(t, k),
                       [ptr.type, _I32, _vec(_I1, k), _vec(t, k)])
    return builder.call(fn, [ptr, ir.Constant(_I32, 8), mask, ir.Constant(_vec(t, k), ir.Undefined)])


def _contiguous(ty, ndim, dtype, layouts="C"):
    return isinstance(ty, types.Array) and ty.ndim == ndim and ty.layout in layouts and ty.dtype == dtype


@intrinsic
def scan_block(typingctx, centres, radius, ids, b, e, box, i, buf, count):
    """Test the box (x0, x1, y0, y1) of object i against slots b .. min(b + LANES, e) - 1 of
    `centres` (n, 2) stored in columns (x of every slot contiguous, as order="F" stores them: the
    caller checks) with `radius` (one float, one per slot, or a box's half-extents (n, 2) per slot,
    stored in columns as the centres are), and write the pairs (min, max) of
    the hits from row `count` of `buf`; returns the new count. Overlap is tested as everywhere
    (closed intervals of x - r, x + r), as two compares per axis: bx0 <= ax1 and ax0 <= bx1 is
    max(ax0, bx0) <= min(ax1, bx1) for boxes of non-negative radii."""
    one, boxes = isinstance(radius, types.Float), _contiguous(radius, 2, types.float64, "F")
    if not (_contiguous(centres, 2, types.float64, "CFA") and _contiguous(ids, 1, types.int64)
            and _contiguous(buf, 2, types.int64) and (one or boxes or _contiguous(radius, 1, types.float64))):
        raise TypeError("scan_block: float64 centres (n, 2), C-contiguous int64 ids and buf (rows, 2), "
                        "and a float64 radius, radii, or half-extents (n, 2) stored in columns")
    sig = types.int64(centres, radius, ids, types.int64, types.int64, types.UniTuple(types.float64, 4),
                      types.int64, buf, types.int64)

    def codegen(context, builder, signature, args):
        centres_v, radius_v, ids_v, b, e, box_v, i, buf_v, count = args
        data = [context.make_array(signature.args[k])(context, builder, v).data
                for k, v in ((0, centres_v), (2, ids_v), (7, buf_v))]
        cdata, idata, bdata = data
        ax0, ax1, ay0, ay1 = (_splat(builder, builder.extract_value(box_v, k), _F64) for k in range(4))
        valid = builder.icmp_signed("<", ir.Constant(_vec(_I64), list(range(LANES))),
                                    _splat(builder, builder.sub(e, b), _I64))
        # Columns: x of every slot, then y, a load each (rows would need two shuffles to split:
        # 1.1x slower on the clustered scene). y starts one column stride after x.
        strides = context.make_array(signature.args[0])(context, builder, centres_v).strides
        y_at = builder.sdiv(builder.extract_value(strides, 1), ir.Constant(_I64, 8))
        xs = _masked_load(builder, builder.gep(cdata, [b]), valid, _F64)
        ys = _masked_load(builder, builder.gep(cdata, [builder.add(b, y_at)]), valid, _F64)
        if one:
            rx = ry = _splat(builder, radius_v, _F64)
        elif boxes:  # half-extents by column, as the centres: x's, then y's one column stride on
            sizes = context.make_array(signature.args[1])(context, builder, radius_v)
            ry_at = builder.sdiv(builder.extract_value(sizes.strides, 1), ir.Constant(_I64, 8))
            rx = _masked_load(builder, builder.gep(sizes.data, [b]), valid, _F64)
            ry = _masked_load(builder, builder.gep(sizes.data, [builder.add(b, ry_at)]), valid, _F64)
        else:
            rdata = context.make_array(signature.args[1])(context, builder, radius_v).data
            rx = ry = _masked_load(builder, builder.gep(rdata, [b]), valid, _F64)
        hit = valid
        for lo, hi in ((builder.fsub(xs, rx), ax1), (ax0, builder.fadd(xs, rx)),
                       (builder.fsub(ys, ry), ay1), (ay0, builder.fadd(ys, ry))):
            hit = builder.and_(hit, builder.fcmp_ordered("<=", lo, hi))
        # The pairs (min, max), interleaved as the buffer's rows are.
        js, iv = _masked_load(builder, builder.gep(idata, [b]), valid, _I64), _splat(builder, i, _I64)
        below = builder.icmp_signed("<", js, iv)
        lo, hi = builder.select(below, js, iv), builder.select(below, iv, js)
        rows = builder.shuffle_vector(lo, hi, ir.Constant(_vec(_I32, 2 * LANES),
                                                          [k // 2 + (LANES if k % 2 else 0) for k in range(2 * LANES)]))
        twice = ir.Constant(_vec(_I32, 2 * LANES), [k // 2 for k in range(2 * LANES)])
        row_hit = builder.shuffle_vector(hit, hit, twice)
        # In halves of LANES // 2 pairs: one 512-bit vector each, compressed in a register and
        # stored whole. A compress straight to memory is microcoded on AMD Zen 4: the clustered
        # scene's pair search took 48 ms that way, 10.5 this way.
        compress = _intrinsic_fn(builder, f"llvm.experimental.vector.compress.v{LANES}i64", _vec(_I64),
                                 [_vec(_I64), _vec(_I1), _vec(_I64)])
        popcount = _intrinsic_fn(builder, "llvm.ctpop.i64", _I64, [_I64])
        bits = builder.zext(builder.bitcast(hit, ir.IntType(LANES)), _I64)
        for k in range(2):
            part = ir.Constant(_vec(_I32), [k * LANES + t for t in range(LANES)])
            packed = builder.call(compress, [builder.shuffle_vector(rows, rows, part),
                                             builder.shuffle_vector(row_hit, row_hit, part),
                                             ir.Constant(_vec(_I64), ir.Undefined)])
            at = builder.gep(bdata, [builder.mul(count, ir.Constant(_I64, 2))])
            builder.store(packed, builder.bitcast(at, ir.PointerType(_vec(_I64))), align=8)
            half = builder.and_(builder.lshr(bits, ir.Constant(_I64, k * LANES // 2)),
                                ir.Constant(_I64, (1 << (LANES // 2)) - 1))
            count = builder.add(count, builder.call(popcount, [half]))
        return count

    return sig, codegen


@nb.njit(cache=True, inline="always")
def scan_compressed(centres, radius, ids, a, box, s, e, buf, count):
    """Slot a (box `box`) against slots s..e-1, LANES at a time; buf needs room for e - s pairs
    past `count` plus SLACK_ROWS."""
    i = ids[a]
    for b in range(s, e, LANES):
        count = scan_block(centres, radius, ids, b, e, box, i, buf, count)
    return count
