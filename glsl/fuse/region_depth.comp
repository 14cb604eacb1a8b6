#version 460
// Per center pixel, its city-block depth inside its region (label_regions.glsl), capped at
// max_depth: one less than the distance to the nearest pixel inside the image of another
// region or unlabeled (0 on the region's edge), max_depth where none lies within max_depth.
// As edge_depth on the host, whose search stays inside the region: the nearest outside
// pixel's straight city-block path crosses no other outside pixel, so both distances
// agree. One invocation per center scans the diamond around it; 0 where there is no pixel.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define pixels UintArray(pc.pixels_addr)
#define out_depth UintArrayRW(pc.depth_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint p = pixels.data[i];
    uint id = p == NO_LABEL ? NO_LABEL : region.data[p];
    if (id == NO_LABEL) {
        out_depth.data[i] = 0u;
        return;
    }
    int x = int(p % pc.width);
    int y = int(p / pc.width);
    int cap = int(pc.max_depth);
    int nearest = cap + 1; // city-block distance to the nearest pixel outside the region
    for (int dy = -cap; dy <= cap; dy++) {
        int qy = y + dy;
        int reach = min(cap - abs(dy), nearest - 1 - abs(dy));
        if (qy < 0 || qy >= int(pc.height) || reach < 0) {
            continue;
        }
        for (int dx = -reach; dx <= reach; dx++) {
            uint q = pixel_at(x + dx, qy);
            if (q != NO_LABEL && region.data[q] != id) {
                nearest = min(nearest, abs(dx) + abs(dy));
            }
        }
    }
    out_depth.data[i] = uint(min(nearest - 1, cap));
}
