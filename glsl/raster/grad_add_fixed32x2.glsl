// Gradient accumulation of blend_backward_body.glsl as 64-bit fixed point on devices
// without int64 atomics: the low word is added first and its carry goes into the high
// word. The final (lo, hi) is the exact 64-bit sum whatever the order (see
// grad_fixed_common.glsl); only the sums read after the dispatch are meaningful.

#include "blend_params.glsl" // the gradient arrays' addresses
#define grad2d UintArrayRW(pc.grad2d_addr)
#define grad_sem UintArrayRW(pc.grad_sem_addr)

#include "grad_fixed_common.glsl"

#define ADD_64(buf, i, q)                                                  \
    {                                                                      \
        uint old = atomicAdd(buf.data[2 * (i)], q.x);                      \
        uint hi = q.y + (old + q.x < old ? 1u : 0u);                       \
        if (hi != 0u) {                                                    \
            atomicAdd(buf.data[2 * (i) + 1], hi);                          \
        }                                                                  \
    }

void grad_add(uint i, float v) {
    uvec2 q;
    if (to_fixed(v, screen_group(i % GRAD2D_STRIDE), q)) {
        ADD_64(grad2d, i, q)
    }
}

void sem_grad_add(uint i, float v) {
    uvec2 q;
    if (to_fixed(v, FIXED_GROUP_SEM, q)) {
        ADD_64(grad_sem, i, q)
    }
}
