// Gradient accumulation of blend_backward_body.glsl for devices without float atomics:
// compare-and-swap on the float bits.

layout(set = 0, binding = 15) buffer Grad2dBuf { uint data[]; } grad2d;
layout(set = 0, binding = 16) buffer GradSemBuf { uint data[]; } grad_sem;

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
