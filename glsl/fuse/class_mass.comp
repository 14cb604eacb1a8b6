#version 460
// Each class row's evidence summed over the whole scene (its scene mass: the semantic
// assignment's last tie-break, src/fuse/assign_gpu.rs). Exact, so the tie-break does not
// depend on summation order: a workgroup sums its span of one row as a 64-bit sum plus a
// count of the sum's carries, and the host adds the workgroups' sums in 128 bits.
// Workgroups: x spans of `span` Gaussians, y rows.
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 256) in;

layout(set = 0, binding = 1) writeonly buffer PartialsBuf { uvec4 data[]; } partials; // [rows][spans]: sum lo, hi, carries, 0

layout(push_constant) uniform MassParams {
    uint n;
    uint words; // words per evidence entry: 1 (vote counts) or 2 (64-bit fixed point)
    uint span;  // Gaussians per workgroup, a multiple of 256
    uint spans; // workgroups per row
    uvec2 evidence_addr; // [rows][n] entries (evidence_entry.glsl)
} pc;

#include "evidence_entry.glsl"

shared uint64_t s_sum[256];
shared uint s_carries[256];

void main() {
    uint lane = gl_LocalInvocationID.x;
    uint row = gl_WorkGroupID.y;
    uint begin = gl_WorkGroupID.x * pc.span;
    uint end = min(begin + pc.span, pc.n);
    uint64_t sum = 0;
    uint carries = 0;
    for (uint g = begin + lane; g < end; g += 256) {
        uint64_t v = evidence_entry(row, g);
        sum += v;
        carries += uint(sum < v);
    }
    s_sum[lane] = sum;
    s_carries[lane] = carries;
    barrier();
    for (uint stride = 128; stride > 0; stride >>= 1) {
        if (lane < stride) {
            uint64_t a = s_sum[lane];
            uint64_t b = a + s_sum[lane + stride];
            s_sum[lane] = b;
            s_carries[lane] += s_carries[lane + stride] + uint(b < a);
        }
        barrier();
    }
    if (lane == 0) {
        partials.data[row * pc.spans + gl_WorkGroupID.x] = uvec4(unpackUint2x32(s_sum[0]), s_carries[0], 0u);
    }
}
