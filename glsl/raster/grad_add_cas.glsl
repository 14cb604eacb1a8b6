// Gradient accumulation of blend_backward_body.glsl for devices without float atomics:
// compare-and-swap on the float bits.

#include "blend_params.glsl" // the gradient arrays' addresses
#define grad2d UintArrayRW(pc.grad2d_addr)
#define grad_sem UintArrayRW(pc.grad_sem_addr)

#define CAS_ADD(buf, i, v)                                                                     \
    {                                                                                          \
        uint old = buf.data[i];                                                                \
        for (;;) {                                                                             \
            uint seen = atomicCompSwap(buf.data[i], old, floatBitsToUint(uintBitsToFloat(old) + (v))); \
            if (seen == old) {                                                                 \
                break;                                                                         \
            }                                                                                  \
            old = seen;                                                                        \
        }                                                                                      \
    }

void grad_add(uint i, float v) {
    CAS_ADD(grad2d, i, v)
}

void sem_grad_add(uint i, float v) {
    CAS_ADD(grad_sem, i, v)
}
