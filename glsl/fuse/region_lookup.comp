#version 460
// Per Gaussian, the region under its center pixel (label_regions.glsl) and whether that
// pixel is on the region's edge: a 4-neighbour inside the image in another region (or
// unlabeled), as region_edges on the host. NO_LABEL where there is no center pixel or it
// is unlabeled. One invocation per Gaussian writes its own entry.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define pixels UintArray(pc.pixels_addr)
#define out_regions UintArrayRW(pc.out_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint p = pixels.data[i];
    uint id = p == NO_LABEL ? NO_LABEL : region.data[p];
    if (id == NO_LABEL) {
        out_regions.data[i] = NO_LABEL;
        return;
    }
    bool edge = false;
    for (uint k = 0u; k < 4u; k++) {
        uint q = neighbour(p, k);
        edge = edge || (q != NO_LABEL && region.data[q] != id);
    }
    out_regions.data[i] = id | (edge ? REGION_EDGE_BIT : 0u);
}
