#version 460
// Writes each decided region's new label into the relabel table (label_regions.glsl),
// which the host filled with RELABEL_KEEP: one invocation per (region id, label) pair.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define decided UintArray(pc.pairs_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < pc.pairs) {
        relabel_table.data[decided.data[2u * i]] = decided.data[2u * i + 1u];
    }
}
