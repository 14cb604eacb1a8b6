#version 460
// Resolves the relabel table's touch entries (RELABEL_TOUCH_BIT | c, label_regions.glsl):
// a mixed region whose centers split between its own label and one other class c keeps its
// label if any of its pixels has a 4-neighbour labeled c (boundary noise gave part of an
// object its neighbour's class), else region_relabel unlabels it (a flicker merge). One
// invocation per pixel; those that find a touch all write the same RELABEL_KEEP, so the
// races between them are benign.

layout(local_size_x = 256) in;

#include "label_regions.glsl"

bool labeled_at(uint q, uint class_id) {
    return labels.data[q] == class_id;
}

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
    uint x = p % pc.width, y = p / pc.width;
    bool touches = (x > 0u && labeled_at(p - 1u, other))
        || (x + 1u < pc.width && labeled_at(p + 1u, other))
        || (y > 0u && labeled_at(p - pc.width, other))
        || (y + 1u < pc.height && labeled_at(p + pc.width, other));
    if (touches) {
        relabel_table.data[r] = RELABEL_KEEP;
    }
}
