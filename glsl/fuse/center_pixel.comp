#version 460
// Where each Gaussian is observed in one view, for the segment consensus (src/fuse/consensus.rs):
// the pixel under its projected center, or NO_LABEL where the center is behind the camera,
// outside the image or (with occlusion on) not within a tolerance of the rendered depth
// there or behind what the pixel shows (the consensus renders the median and opaque
// depths: raster/blend_median_depth.comp). The host reads that pixel's label and connected
// label region. One invocation per Gaussian writes its own entry, so no atomics are needed.

layout(local_size_x = 256) in;

layout(set = 0, binding = 1) readonly buffer DepthBuf { float data[]; } depth;
layout(set = 0, binding = 2) readonly buffer OpaqueDepthBuf { float data[]; } opaque_depth;

#define OPAQUE_DEPTH_TEST

#include "center_pixel.glsl"
#define pixels UintArrayRW(pc.out_addr) // [n]
#define spatial UintArray(pc.spatial_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < pc.n) {
        // Numbered in space (src/fuse/consensus_order.rs), each Gaussian's entry goes at its
        // number, so the observations compacted from the entries come in that order and
        // carry that number, with no sort on the host. A device address is never 0.
        uint at = i;
        if (any(notEqual(pc.spatial_addr, uvec2(0u)))) {
            at = spatial.data[i];
        }
        pixels.data[at] = center_pixel(i);
    }
}
