// Connected label regions of one view on the GPU, for the segment consensus
// (src/fuse/regions_gpu.rs; the host version is label_regions in
// src/fuse/consensus_segments.rs). Union-find over the pixels (4-neighbourhood of equal
// labels): every pixel starts as its own root, each joins its left and upper neighbour of
// the same label by linking the larger root under the smaller with atomicMin, so a region's
// root is its first pixel in scan order whatever order the invocations run in. The region
// id is that pixel's index, as on the host. Kernels, one per file: region_init,
// region_merge, region_flatten, region_check (a pass that finds any link the loop cap of a
// CPU driver cut short, so the host can redo that view), region_lookup (per Gaussian),
// observed_flag and observed_compact (each view's observations, compacted); for
// relabeling a view (src/fuse/consensus_relabel.rs): region_depth and region_near (per
// center pixel), region_relabel_scatter (per decided region) and region_relabel (per
// pixel).
#ifndef LABEL_REGIONS_GLSL
#define LABEL_REGIONS_GLSL

#include "shared_constants.glsl" // NO_LABEL, REGION_EDGE_BIT

layout(push_constant) uniform RegionParams {
    uvec2 labels_addr; // [pixels] the view's labels (NO_LABEL: unlabeled)
    uvec2 parent_addr; // [pixels] union-find links (NO_LABEL where unlabeled)
    uvec2 region_addr; // [pixels] each pixel's root: its region id
    uvec2 status_addr; // [1] 0, or 1 once region_check found a pixel not joined
    uvec2 pixels_addr; // [n] each Gaussian's center pixel (NO_LABEL: none)
    uvec2 out_addr;    // [n] region id of the center pixel, bit 31 set on the region's edge
    uvec2 depth_addr;  // [n] city-block depth of the center pixel in its region, capped
    uvec2 pairs_addr;  // [2 * pairs] (region id, new label) of each region relabeled
    uvec2 classes_addr; // [n] the consensus class of each center pixel's Gaussian
    uvec2 near_addr;   // [n] 1 where a pixel of that class lies within near_radius, else 0
    uvec2 slots_addr;  // [n] 1 where out_addr holds a region, then each observation's place
    uvec2 observed_addr; // host-visible: the count, then the view's observations in order
    uint width;
    uint height;
    uint n;
    uint max_depth;    // region_depth's cap
    uint near_radius;  // region_near's reach
    uint pairs;
} pc;

#include "addressed_arrays.glsl"
#define labels UintArray(pc.labels_addr)
#define parent UintArrayCoherent(pc.parent_addr)
#define region UintArrayRW(pc.region_addr)
// Relabeling reuses the links, done with once the ids are flat, as the per-region table
// (indexed by region id, the root pixel) of new labels.
#define relabel_table UintArrayRW(pc.parent_addr)

uint pixel_count() {
    return pc.width * pc.height;
}

// Pixel p's k-th 4-neighbour (k = 0..3: left, right, up, down), or NO_LABEL outside the
// image (src/fuse/consensus_segments.rs four_neighbours on the host).
uint neighbour(uint p, uint k) {
    uint x = p % pc.width, y = p / pc.width;
    switch (k) {
    case 0u: return x > 0u ? p - 1u : NO_LABEL;
    case 1u: return x + 1u < pc.width ? p + 1u : NO_LABEL;
    case 2u: return y > 0u ? p - pc.width : NO_LABEL;
    default: return y + 1u < pc.height ? p + pc.width : NO_LABEL;
    }
}

// Pixel (x, y)'s index, or NO_LABEL outside the image: the diamond searches of region_depth
// and region_near.
uint pixel_at(int x, int y) {
    bool inside = x >= 0 && y >= 0 && x < int(pc.width) && y < int(pc.height);
    return inside ? uint(y) * pc.width + uint(x) : NO_LABEL;
}

// The root of pixel p's tree (links only point to smaller indices, so this ends), each
// link on the way moved up to its grandparent (path halving). On a GPU the unions chain a
// region's rows at once, each pixel under its left neighbour, and a plain walk from a pixel
// went back to its row's start: a model of the merge on a 1080p segmenter's map (270,000
// invocations at a time, one step each a round) walked 1,068 links a pixel and 10,841
// rounds, 16 and 138 with halving, since the walkers of one chain halve it for each other
// (docs/gpu.md). atomicMin, so a link only ever moves to a smaller pixel of the same
// region, whatever another union or walk set there meanwhile: the roots, and so the ids,
// are the same in any order.
uint find_root(uint p) {
    uint up = parent.data[p];
    while (up != p) {
        uint upup = parent.data[up];
        if (upup != up) {
            atomicMin(parent.data[p], upup);
        }
        p = upup;
        up = parent.data[p];
    }
    return p;
}

#endif
