// Contributions as 64-bit fixed point (fuse/fixed_amounts.glsl) into the pass's evidence rows.
#include "fixed_amounts.glsl"

#define contrib U64ArrayRW(pc.contrib_addr) // [rows][n]

void add_fixed(uint row, uint gaussian, uint64_t amount) {
    atomicAdd(contrib.data[row * pc.n + gaussian], amount);
}
