#version 460
// Emits one (tile id, Gaussian id) pair per tile each visible Gaussian covers within the
// rows this binning covers, in depth order, so a stable sort by tile id leaves every tile's
// list sorted by depth. Pairs past the buffer's capacity are dropped and the overflow is
// flagged for the host to grow it (or bin the view in smaller bands of rows).
//
// Load-balanced: a workgroup takes 256 consecutive Gaussians and its invocations write
// their pairs together, slot by slot, each finding its slot's Gaussian by a binary search
// of the group's first slots in shared memory. One invocation per Gaussian writing all of
// its tiles left most lanes idle behind the largest Gaussian of their subgroup and scattered
// every store; here consecutive invocations store consecutive slots. An invocation writes
// at most as many pairs as the largest Gaussian of its group covers (the group's total over
// 256), and the search is unrolled, so it stays under lavapipe's loop cap wherever one
// invocation per Gaussian did.
#extension GL_EXT_control_flow_attributes : require
#include "raster_common.glsl"

#define EMIT_GROUP 256
layout(local_size_x = EMIT_GROUP) in;

#include "emit_common.glsl"

// Per Gaussian of the group: its first slot, id, first tile column, first tile row binned
// and width in tiles.
shared uint s_first_slot[EMIT_GROUP];
shared uint s_id[EMIT_GROUP];
shared uint s_x0[EMIT_GROUP];
shared uint s_y0[EMIT_GROUP];
shared uint s_width[EMIT_GROUP];

// Loads invocation `lane`'s Gaussian (depth order `j`) into shared memory; past the visible
// ones, an empty entry at the total.
void load_gaussian(uint lane, uint j, uint v) {
    s_first_slot[lane] = isect_offsets.data[min(j, v)];
    s_id[lane] = 0;
    s_x0[lane] = 0;
    s_y0[lane] = 0;
    s_width[lane] = 1;
    if (j < v) {
        // The offsets are a 32-bit exclusive scan of the tile counts: where the running
        // total passes 2^32 - 1, the next offset is smaller than this one. Flag it for the
        // host, which refuses the frame (every list after the wrap would be wrong).
        if (isect_offsets.data[j + 1] < isect_offsets.data[j]) {
            status.data[ST_ISECT_WRAPPED] = 1;
        }
        uint g = depth_ids.data[j];
        uvec4 r = tile_rects.data[g];
        s_id[lane] = g;
        s_x0[lane] = r.x;
        s_y0[lane] = max(r.y, pc.row_begin);
        s_width[lane] = max(r.z - r.x, 1);
    }
}

// The group's Gaussian (index into the shared arrays) whose pairs hold `slot`: the last one
// whose first slot is at most `slot` (those before it with no pairs share its first slot).
uint gaussian_of(uint slot) {
    uint lo = 0;
    [[unroll]] for (uint step = EMIT_GROUP / 2; step > 0; step >>= 1) {
        if (s_first_slot[lo + step] <= slot) {
            lo += step;
        }
    }
    return lo;
}

void main() {
    uint lane = gl_LocalInvocationID.x;
    uint first = gl_WorkGroupID.x * EMIT_GROUP;
    uint j = first + lane;
    uint v = status.data[ST_VISIBLE];
    if (j == v) {
        write_totals(v);
    }
    load_gaussian(lane, j, v);
    barrier();
    // Past the capacity pairs are dropped, so a frame that overflows costs no more than the
    // capacity to find out.
    uint begin = s_first_slot[0];
    uint end = min(isect_offsets.data[min(first + EMIT_GROUP, v)], pc.capacity);
    for (uint slot = begin + lane; slot < end; slot += EMIT_GROUP) {
        uint i = gaussian_of(slot);
        uint k = slot - s_first_slot[i];
        uint w = s_width[i];
        isect_keys.data[slot] = (s_y0[i] + k / w) * pc.tiles_x + s_x0[i] + k % w;
        isect_ids.data[slot] = s_id[i];
    }
}
