#version 460
// Compacts the visible Gaussians in index order (positions from the scan of the flags, so
// the order is deterministic) as depth-sort keys: the bits of a positive float order like
// the float. Invocation n publishes the visible count and the next dispatch size.
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform CompactParams {
    uvec2 xy_depth_opacity_addr; // per Gaussian (gaussian_arrays.glsl)
    uint n;
} pc;

#include "gaussian_arrays.glsl"
#define xy_depth_opacity Vec4Array(pc.xy_depth_opacity_addr)

layout(set = 0, binding = 0) readonly buffer FlagsBuf { uint data[]; } visible;
layout(set = 0, binding = 1) readonly buffer OffsetsBuf { uint data[]; } visible_offsets; // n + 1
layout(set = 0, binding = 3) writeonly buffer KeysBuf { uint data[]; } depth_keys;
layout(set = 0, binding = 4) writeonly buffer IdsBuf { uint data[]; } depth_ids;
layout(set = 0, binding = 5) writeonly buffer StatusBuf { uint data[]; } status;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i > pc.n) {
        return;
    }
    if (i == pc.n) {
        uint v = visible_offsets.data[pc.n];
        status.data[ST_VISIBLE] = v;
        status.data[ST_VISIBLE_PLUS1] = v + 1;
        status.data[ST_ARGS_VISIBLE + 0] = (v + 1 + 255) / 256;
        status.data[ST_ARGS_VISIBLE + 1] = 1;
        status.data[ST_ARGS_VISIBLE + 2] = 1;
        return;
    }
    if (visible.data[i] != 0) {
        uint j = visible_offsets.data[i];
        depth_keys.data[j] = floatBitsToUint(xy_depth_opacity.data[i].z);
        depth_ids.data[j] = i;
    }
}
