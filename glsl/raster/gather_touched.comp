#version 460
// Tile counts of the visible Gaussians in depth order (and a trailing zero), for the scan
// that gives each Gaussian its first intersection slot.
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(set = 0, binding = 0) readonly buffer StatusBuf { uint data[]; } status;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } depth_ids;
layout(set = 0, binding = 2) readonly buffer TouchedBuf { uint data[]; } tiles_touched;
layout(set = 0, binding = 3) writeonly buffer SortedTouchedBuf { uint data[]; } sorted_touched;

void main() {
    uint j = gl_GlobalInvocationID.x;
    uint v = status.data[ST_VISIBLE];
    if (j < v) {
        sorted_touched.data[j] = tiles_touched.data[depth_ids.data[j]];
    } else if (j == v) {
        sorted_touched.data[j] = 0;
    }
}
