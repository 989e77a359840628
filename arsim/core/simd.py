"""Four-lane float32 arithmetic for compiled kernels whose textures hold RGBA float32 texels: one texel is one
16-byte vector. numba's compiler vectorises loops across their iterations (gathers: a texel's four channels
in four gathers) and does not find the vector in a texel's channels; these intrinsics spell it out, so that a
weighted sum of four texels is four vector loads and four fused multiply-adds (README: `mc` and the speed of
`sh` over its orders)."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

RGBA = types.UniTuple(types.float32, 4)


def _splat(builder, value, vector):
    out = ir.Constant(vector, ir.Undefined)
    for lane in range(4):
        out = builder.insert_element(out, value, ir.Constant(ir.IntType(32), lane))
    return out


@intrinsic
def accumulate_texels(typingctx, acc, flat, index, weights):
    """acc + sum_k weights[k] * texel(index[k]), lane by lane: acc and weights 4-tuples of float32, flat a 1-D
    float32 array of RGBA texels (texel i is flat[4 i : 4 i + 4]), index a 4-tuple of texel indices (not
    checked against the array's bounds)."""
    if (acc != RGBA or weights != RGBA or not isinstance(flat, types.Array) or flat.dtype != types.float32
            or flat.ndim != 1 or not isinstance(index, types.UniTuple) or len(index) != 4
            or not isinstance(index.dtype, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        acc_value, flat_value, index_value, weight_value = args
        data = context.make_array(signature.args[1])(context, builder, flat_value).data
        vector = ir.VectorType(ir.FloatType(), 4)
        total = ir.Constant(vector, ir.Undefined)
        for lane in range(4):
            total = builder.insert_element(total, builder.extract_value(acc_value, lane), ir.Constant(ir.IntType(32), lane))
        # (the fused multiply-add spelled out: one rounding wherever the code is compiled; a multiply and an add
        # that the compiler was free to fuse gave other last bits in a fresh compile than in numba's cached one)
        fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vector, [vector] * 3), "llvm.fma.v4f32")
        for k in range(4):
            at = builder.mul(builder.sext(builder.extract_value(index_value, k), ir.IntType(64)), ir.Constant(ir.IntType(64), 4))
            texel = builder.load(builder.bitcast(builder.gep(data, [at]), vector.as_pointer()), align=4)
            total = builder.call(fma, [texel, _splat(builder, builder.extract_value(weight_value, k), vector), total])
        lanes = [builder.extract_element(total, ir.Constant(ir.IntType(32), lane)) for lane in range(4)]
        return context.make_tuple(builder, signature.return_type, lanes)

    return RGBA(acc, flat, index, weights), codegen
