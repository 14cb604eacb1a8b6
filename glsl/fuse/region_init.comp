#version 460
// Every labeled pixel its own root; unlabeled pixels link nowhere (label_regions.glsl).

layout(local_size_x = 256) in;

#include "label_regions.glsl"

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p < pixel_count()) {
        parent.data[p] = labels.data[p] == NO_LABEL ? NO_LABEL : p;
    }
}
