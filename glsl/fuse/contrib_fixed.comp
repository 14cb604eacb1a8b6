#version 460
// Contributions as 64-bit fixed point (weight * 2^32): integer sums do not depend on the
// order of the atomics, so A is bit-identical from run to run.
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#include "contrib_body.glsl"

layout(buffer_reference, std430, buffer_reference_align = 8) buffer U64ArrayRW { uint64_t data[]; };
#define contrib U64ArrayRW(pc.contrib_addr) // [rows][n]

void accumulate(uint row, uint gaussian, float w) {
    // w < 1, so its fixed-point value fits 32 bits; summing 16-bit halves keeps the
    // subgroup sums exact for up to 65,536 lanes.
    uint v = row == NO_ROW ? 0u : uint(min(w * 4294967296.0, 4294967295.0));
    if (subgroupAllEqual(row)) {
        if (row != NO_ROW) {
            uint lo = subgroupAdd(v & 0xFFFFu);
            uint hi = subgroupAdd(v >> 16);
            if (subgroupElect()) {
                atomicAdd(contrib.data[row * pc.n + gaussian], (uint64_t(hi) << 16) + uint64_t(lo));
            }
        }
    } else if (row != NO_ROW) {
        atomicAdd(contrib.data[row * pc.n + gaussian], uint64_t(v));
    }
}
