// Gradient accumulation of blend_backward_body.glsl as 64-bit fixed point with int64
// atomics (order-independent: see grad_fixed_common.glsl).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require

layout(set = 0, binding = 15) buffer Grad2dBuf { uint64_t data[]; } grad2d;
layout(set = 0, binding = 16) buffer GradSemBuf { uint64_t data[]; } grad_sem;

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
