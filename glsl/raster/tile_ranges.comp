#version 460
// Start and end (exclusive) of every tile's run in the tile-sorted intersection list.
// Tiles without intersections keep the (0, 0) the host filled in.
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(set = 0, binding = 0) readonly buffer StatusBuf { uint data[]; } status;
layout(set = 0, binding = 1) readonly buffer KeysBuf { uint data[]; } isect_keys;
layout(set = 0, binding = 2) writeonly buffer RangesBuf { uvec2 data[]; } tile_ranges;

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint total = status.data[ST_ISECT];
    if (i >= total) {
        return;
    }
    uint t = isect_keys.data[i];
    if (i == 0 || isect_keys.data[i - 1] != t) {
        tile_ranges.data[t].x = i;
    }
    if (i == total - 1 || isect_keys.data[i + 1] != t) {
        tile_ranges.data[t].y = i + 1;
    }
}
