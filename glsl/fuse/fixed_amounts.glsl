// Weights as 64-bit fixed point (weight * 2^32), summed in the subgroup where its lanes share
// a row: integer sums do not depend on the order of the atomics, so the totals are
// bit-identical from run to run. Included (in place of contrib_body.glsl) by the includers
// that sum in fixed point; each defines `add_fixed(row, target, amount)`, the atomic that
// adds an amount where it belongs (fuse/contrib_fixed.glsl: the evidence rows;
// fuse/region_footprint.glsl: a list entry's sums per region).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#define Amount uint64_t
#include "contrib_body.glsl"

layout(buffer_reference, std430, buffer_reference_align = 8) buffer U64ArrayRW { uint64_t data[]; };

void add_fixed(uint row, uint target, uint64_t amount);

// A weight w < 1 of one pixel as fixed point: it fits 32 bits.
uint64_t amount_of(float w) {
    return uint64_t(uint(min(w * 4294967296.0, 4294967295.0)));
}

void accumulate(uint row, uint target, uint64_t amount) {
    // An invocation's amount sums PIXELS pixels' (32 + log2(PIXELS) bits); summing its
    // 16-bit parts keeps the subgroup sums exact for up to 65,536 lanes.
    uint64_t v = row == NO_ROW ? 0ul : amount;
    if (subgroupAllEqual(row)) {
        if (row != NO_ROW) {
            uint lo = subgroupAdd(uint(v) & 0xFFFFu);
            uint hi = subgroupAdd(uint(v) >> 16);
            uint64_t sum = (uint64_t(hi) << 16) + uint64_t(lo);
#if PIXELS > 1
            sum += uint64_t(subgroupAdd(uint(v >> 32))) << 32;
#endif
            if (subgroupElect()) {
                add_fixed(row, target, sum);
            }
        }
    } else if (row != NO_ROW) {
        add_fixed(row, target, v);
    }
}

void add_own(uint row, uint target, uint64_t amount) {
    add_fixed(row, target, amount);
}
