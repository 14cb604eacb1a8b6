#version 460
// Densifies the first DS_DENSIFIED candidates in sorted order (largest average gradient
// first, ties by index; in index order when all fit): each now has two output slots.
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(set = 0, binding = 0) readonly buffer StatusBuf { uint data[]; } status;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } candidate_ids;
layout(set = 0, binding = 2) writeonly buffer OutCountBuf { uint data[]; } out_count;

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p < status.data[DS_DENSIFIED]) {
        out_count.data[candidate_ids.data[p]] = 2;
    }
}
