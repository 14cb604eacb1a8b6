// Gradient accumulation of blend_backward_body.glsl with float32 atomic adds
// (VK_EXT_shader_atomic_float).
#extension GL_EXT_shader_atomic_float : require

#include "blend_params.glsl" // the gradient arrays' addresses
#define grad2d FloatArrayRW(pc.grad2d_addr)
#define grad_sem FloatArrayRW(pc.grad_sem_addr)

void grad_add(uint i, float v) {
    atomicAdd(grad2d.data[i], v);
}

void sem_grad_add(uint i, float v) {
    atomicAdd(grad_sem.data[i], v);
}
