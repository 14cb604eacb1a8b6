#version 460
// Rewrites every labeled pixel with its region's entry of the relabel table (a compact
// class, or NO_LABEL: unlabeled) unless the entry is RELABEL_KEEP (label_regions.glsl).

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define labels_out UintArrayRW(pc.labels_addr)

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pixel_count() || labels_out.data[p] == NO_LABEL) {
        return;
    }
    uint label = relabel_table.data[region.data[p]];
    if (label != RELABEL_KEEP) {
        labels_out.data[p] = label;
    }
}
