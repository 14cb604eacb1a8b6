// Gradient accumulation of blend_backward_body.glsl as 64-bit fixed point with int64
// atomics (order-independent: see grad_fixed_common.glsl).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

#include "blend_params.glsl" // the gradient arrays' addresses
layout(buffer_reference, std430, buffer_reference_align = 8) buffer U64ArrayRW { uint64_t data[]; };
#define grad2d U64ArrayRW(pc.grad2d_addr)
#define grad_sem U64ArrayRW(pc.grad_sem_addr)

#include "grad_fixed_common.glsl"

void grad_add(uint i, float v) {
    uvec2 q;
    if (to_fixed(v, screen_group(i % GRAD2D_STRIDE), q)) {
        atomicAdd(grad2d.data[i], packUint2x32(q));
    }
}

void sem_grad_add(uint i, float v) {
    uvec2 q;
    if (to_fixed(v, FIXED_GROUP_SEM, q)) {
        atomicAdd(grad_sem.data[i], packUint2x32(q));
    }
}
