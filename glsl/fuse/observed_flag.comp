#version 460
// Per Gaussian, 1 where region_lookup found a labeled pixel under its center (an
// observation of this view), else 0: the input of the prefix scan that gives each
// observation its place (observed_compact). One invocation per Gaussian.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define looked_up UintArray(pc.out_addr)
#define slots UintArrayRW(pc.slots_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    slots.data[i] = looked_up.data[i] == NO_LABEL ? 0u : 1u;
}
