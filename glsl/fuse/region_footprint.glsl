// `--relabel`'s footprints (src/fuse/consensus_footprints.rs): FlashSplat's walk of one view
// with each labeled pixel's weight added per (entry of its tile's list, the pixel's label
// region), and each labeled pixel's median and opaque depths written on the way, so the
// consensus's observation pass needs no walk of its own for its occlusion test. Once the
// consensus has decided, the host adds each entry's sum for a region to the entry's
// Gaussian's row of the class that region was relabeled to: the integers FlashSplat's
// accumulation over the relabeled views sums, without walking the views again.
//
// The labels binding holds, per pixel, the index of its region among its tile's regions
// (NO_LABEL: unlabeled), pc.rows the most regions a tile of the view holds. A tile's list
// entries are walked by that tile's workgroup alone, so the sums are addressed by entry
// ([rows][pc.n] at contrib_addr, pc.n the lists' capacity): no search for a Gaussian's slot
// of a region. A row holds the entries side by side, as the batches load them.
#define MEDIAN_DEPTH_OUT
#define ENTRY_TARGETS
#include "fixed_amounts.glsl"

#define sums U64ArrayRW(pc.contrib_addr) // [rows][pc.n]

void add_fixed(uint region, uint entry, uint64_t amount) {
    atomicAdd(sums.data[region * pc.n + entry], amount);
}
