#version 460
// Densifies the first DS_DENSIFIED candidates in sorted order (largest average gradient
// first, ties by index; in index order when all fit): each now has two output slots.
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform DensifySelectParams {
    // By address (addressed_arrays.glsl): the sorted candidates' ids, and the output count
    // of every Gaussian ([n + 1]).
    uvec2 candidate_ids_addr;
    uvec2 out_count_addr;
} pc;

#include "addressed_arrays.glsl"
#define candidate_ids UintArray(pc.candidate_ids_addr)
#define out_count UintArrayRW(pc.out_count_addr)

layout(set = 0, binding = 0) readonly buffer StatusBuf { uint data[]; } status;

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p < status.data[DS_DENSIFIED]) {
        out_count.data[candidate_ids.data[p]] = 2;
    }
}
