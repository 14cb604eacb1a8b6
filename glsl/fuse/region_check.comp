#version 460
// Sets the status word where the regions are not complete (label_regions.glsl): a pixel
// whose id is not a root, or a left or upper neighbour of the same label with another id.
// Only a loop cut short can cause that (a CPU driver caps the iterations of an invocation);
// the host then finds that view's regions itself. No loops here.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define status UintArrayRW(pc.status_addr)

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pixel_count()) {
        return;
    }
    uint label = labels.data[p];
    if (label == NO_LABEL) {
        return;
    }
    uint id = region.data[p];
    bool broken = id >= pixel_count() || region.data[id] != id || labels.data[id] != label;
    if (!broken && p % pc.width > 0 && labels.data[p - 1] == label) {
        broken = region.data[p - 1] != id;
    }
    if (!broken && p >= pc.width && labels.data[p - pc.width] == label) {
        broken = region.data[p - pc.width] != id;
    }
    if (broken) {
        status.data[0] = 1;
    }
}
