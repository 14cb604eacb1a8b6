#version 460
// Joins every labeled pixel with its left and upper neighbour of the same label
// (label_regions.glsl). Lock-free union: the larger root is linked under the smaller with
// atomicMin; when another invocation linked it first, the union goes on from the root it
// was linked to.

layout(local_size_x = 256) in;

#include "label_regions.glsl"

void join(uint a, uint b) {
    for (;;) {
        a = find_root(a);
        b = find_root(b);
        if (a == b) {
            return;
        }
        uint hi = max(a, b);
        uint lo = min(a, b);
        uint was = atomicMin(parent.data[hi], lo);
        if (was == hi) {
            return; // hi was a root and now hangs under lo
        }
        // hi had been linked meanwhile: join its new parent with lo.
        a = was;
        b = lo;
    }
}

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pixel_count()) {
        return;
    }
    uint label = labels.data[p];
    if (label == NO_LABEL) {
        return;
    }
    if (p % pc.width > 0 && labels.data[p - 1] == label) {
        join(p, p - 1);
    }
    if (p >= pc.width && labels.data[p - pc.width] == label) {
        join(p, p - pc.width);
    }
}
