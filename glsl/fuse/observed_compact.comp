#version 460
// Each observation of the view written at its place in Gaussian order (slots: the exclusive
// prefix sum of observed_flag) as (Gaussian, center pixel, label, region id with
// REGION_EDGE_BIT), after OBSERVED_HEADER_WORDS whose first the last Gaussian sets to the
// count. The output is host-visible memory: the host reads the observations alone (about
// one Gaussian in eight per view at 1080p) instead of two words for every Gaussian.
// One invocation per Gaussian.

layout(local_size_x = 256) in;

#include "label_regions.glsl"
#define pixels UintArray(pc.pixels_addr)
#define looked_up UintArray(pc.out_addr)
#define slots UintArray(pc.slots_addr)
#define observed UintArrayRW(pc.observed_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint id = looked_up.data[i];
    uint slot = slots.data[i];
    if (id != NO_LABEL) {
        uint p = pixels.data[i];
        uint at = OBSERVED_HEADER_WORDS + slot * OBSERVED_WORDS;
        observed.data[at] = i;
        observed.data[at + 1u] = p;
        observed.data[at + 2u] = labels.data[p];
        observed.data[at + 3u] = id;
    }
    if (i + 1u == pc.n) {
        observed.data[0] = slot + (id != NO_LABEL ? 1u : 0u);
    }
}
