#version 460
// Resolves the relabel table's touch entries (RELABEL_TOUCH_BIT | c, label_regions.glsl):
// a mixed region whose centers split between its own label and one other class c keeps its
// label if any of its pixels has a 4-neighbour labeled c (boundary noise gave part of an
// object its neighbour's class), else region_relabel unlabels it (a flicker merge). One
// invocation per pixel; those that find a touch all write the same RELABEL_KEEP, so the
// races between them are benign.

layout(local_size_x = 256) in;

#include "label_regions.glsl"

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pixel_count() || labels.data[p] == NO_LABEL) {
        return;
    }
    uint r = region.data[p];
    uint entry = relabel_table.data[r];
    if (!is_touch_entry(entry)) {
        return;
    }
    uint other = entry & ~RELABEL_TOUCH_BIT;
    for (uint k = 0u; k < 4u; k++) {
        uint q = neighbour(p, k);
        if (q != NO_LABEL && labels.data[q] == other) {
            relabel_table.data[r] = RELABEL_KEEP;
            return;
        }
    }
}
