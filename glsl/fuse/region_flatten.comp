#version 460
// Each pixel's region id: the root of its tree (label_regions.glsl). Written to a separate
// array: relabeling reuses the links as its per-region table once the ids are flat. The
// walks still move links (find_root's halving), only ever to a grandparent: the same root.

layout(local_size_x = 256) in;

#include "label_regions.glsl"

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p < pixel_count()) {
        region.data[p] = parent.data[p] == NO_LABEL ? NO_LABEL : find_root(p);
    }
}
