#version 460
// Compacts the visible Gaussians in index order (positions from the scan of the flags, so
// the order is deterministic) as depth-sort keys: the bits of a positive float order like
// the float. Invocation n publishes the visible count and the next dispatch size.
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform CompactParams {
    // Per Gaussian, by address (addressed_arrays.glsl): the flags and their scan (n + 1
    // each), the projected attributes, and the depth keys and ids written.
    uvec2 visible_addr;
    uvec2 visible_offsets_addr;
    uvec2 xy_depth_opacity_addr;
    uvec2 depth_keys_addr;
    uvec2 depth_ids_addr;
    uint n;
} pc;

#include "addressed_arrays.glsl"
#define visible UintArray(pc.visible_addr)
#define visible_offsets UintArray(pc.visible_offsets_addr)
#define xy_depth_opacity Vec4Array(pc.xy_depth_opacity_addr)
#define depth_keys UintArrayRW(pc.depth_keys_addr)
#define depth_ids UintArrayRW(pc.depth_ids_addr)

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
