#version 460
// One Adam step on one parameter tensor, in place (as torch.optim.Adam with the bias
// corrections folded into step_size and sqrt_bc2 on the host). The gradient is read, not
// cleared. Grid-stride, so tensors past 65,535 workgroups of elements need no 2D grid.

layout(local_size_x = 256) in;

layout(push_constant) uniform AdamParams {
    uint count;
    float beta1;
    float beta2;
    // 1 - beta from the host in f64: 1.0 - 0.999 in f32 is off by 1.3e-5 relative.
    float one_minus_beta1;
    float one_minus_beta2;
    float eps;
    float step_size; // lr / (1 - beta1^t)
    float sqrt_bc2;  // sqrt(1 - beta2^t)
} pc;

layout(set = 0, binding = 0) buffer ParamBuf { float data[]; } param;
layout(set = 0, binding = 1) readonly buffer GradBuf { float data[]; } grad;
layout(set = 0, binding = 2) buffer MomentBuf { float data[]; } exp_avg;
layout(set = 0, binding = 3) buffer SecondMomentBuf { float data[]; } exp_avg_sq;

void main() {
    uint threads = gl_NumWorkGroups.x * 256;
    for (uint i = gl_GlobalInvocationID.x; i < pc.count; i += threads) {
        float g = grad.data[i];
        float m = pc.beta1 * exp_avg.data[i] + pc.one_minus_beta1 * g;
        float v = pc.beta2 * exp_avg_sq.data[i] + pc.one_minus_beta2 * g * g;
        exp_avg.data[i] = m;
        exp_avg_sq.data[i] = v;
        param.data[i] -= pc.step_size * m / (sqrt(v) / pc.sqrt_bc2 + pc.eps);
    }
}
