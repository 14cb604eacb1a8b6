// Gradient accumulation of blend_backward_body.glsl with float32 atomic adds
// (VK_EXT_shader_atomic_float).
#extension GL_EXT_shader_atomic_float : require

layout(set = 0, binding = 15) buffer Grad2dBuf { float data[]; } grad2d;
layout(set = 0, binding = 16) buffer GradSemBuf { float data[]; } grad_sem;

void grad_add(uint i, float v) {
    atomicAdd(grad2d.data[i], v);
}

void sem_grad_add(uint i, float v) {
    atomicAdd(grad_sem.data[i], v);
}
