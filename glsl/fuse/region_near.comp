#version 460
// Per center pixel, whether a pixel labeled its Gaussian's consensus class lies within
// near_radius of it (city-block): 1 if so (or if its own pixel has that label), else 0.
// A region's centers of another class than its label that lie this near a pixel of their
// class are the mark of a label edge drawn a few pixels off (boundary noise), not of a
// flicker merge (src/fuse/consensus_relabel.rs, RelabelRule::near). One invocation per
// center scans the diamond around it; 0 where there is no pixel.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define pixels UintArray(pc.pixels_addr)
#define classes UintArray(pc.classes_addr)
#define out_near UintArrayRW(pc.near_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint p = pixels.data[i];
    if (p == NO_LABEL) {
        out_near.data[i] = 0u;
        return;
    }
    uint class_id = classes.data[i];
    if (labels.data[p] == class_id) {
        out_near.data[i] = 1u; // most centers: their own pixel (no search)
        return;
    }
    int x = int(p % pc.width);
    int y = int(p / pc.width);
    int r = int(pc.near_radius);
    uint near = 0u;
    for (int dy = -r; dy <= r && near == 0u; dy++) {
        int qy = y + dy;
        int reach = r - abs(dy);
        if (qy < 0 || qy >= int(pc.height)) {
            continue;
        }
        for (int dx = -reach; dx <= reach; dx++) {
            uint q = pixel_at(x + dx, qy);
            if (q != NO_LABEL && labels.data[q] == class_id) {
                near = 1u;
                break;
            }
        }
    }
    out_near.data[i] = near;
}
