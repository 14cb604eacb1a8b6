#version 460
// Emits one (tile id, Gaussian id) pair per tile each visible Gaussian covers within the
// rows this binning covers, in depth order, so a stable sort by tile id leaves every tile's
// list sorted by depth. Pairs past the buffer's capacity are dropped and the overflow is
// flagged for the host to grow it (or bin the view in smaller bands of rows).
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform EmitParams {
    uint tiles_x;
    uint capacity;
    uint row_begin; // first tile row binned (see gather_touched.comp)
    uint row_end;   // one past the last
} pc;

layout(set = 0, binding = 0) buffer StatusBuf { uint data[]; } status;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } depth_ids;
layout(set = 0, binding = 2) readonly buffer OffsetsBuf { uint data[]; } isect_offsets; // V + 1
layout(set = 0, binding = 3) readonly buffer RectBuf { uvec4 data[]; } tile_rects;
layout(set = 0, binding = 4) writeonly buffer KeysBuf { uint data[]; } isect_keys;
layout(set = 0, binding = 5) writeonly buffer ValsBuf { uint data[]; } isect_ids;

void main() {
    uint j = gl_GlobalInvocationID.x;
    uint v = status.data[ST_VISIBLE];
    if (j > v) {
        return;
    }
    if (j == v) {
        uint needed = isect_offsets.data[v];
        uint kept = min(needed, pc.capacity);
        status.data[ST_ISECT] = kept;
        status.data[ST_ISECT_NEEDED] = needed;
        status.data[ST_OVERFLOW] = needed > pc.capacity ? 1 : 0;
        status.data[ST_ARGS_ISECT + 0] = (kept + 255) / 256;
        status.data[ST_ARGS_ISECT + 1] = 1;
        status.data[ST_ARGS_ISECT + 2] = 1;
        return;
    }
    uint slot = isect_offsets.data[j];
    // The offsets are a 32-bit exclusive scan of the tile counts: where the running total
    // passes 2^32 - 1, the next offset is smaller than this one. Flag it for the host,
    // which refuses the frame (every list after the wrap would be wrong).
    if (isect_offsets.data[j + 1] < slot) {
        status.data[ST_ISECT_WRAPPED] = 1;
    }
    // Pairs past the capacity are dropped: leave as soon as one is, so a frame that
    // overflows costs no more than the capacity to find out.
    if (slot >= pc.capacity) {
        return;
    }
    uint g = depth_ids.data[j];
    uvec4 r = tile_rects.data[g];
    for (uint ty = max(r.y, pc.row_begin); ty < min(r.w, pc.row_end); ty++) {
        for (uint tx = r.x; tx < r.z; tx++) {
            if (slot >= pc.capacity) {
                return;
            }
            isect_keys.data[slot] = ty * pc.tiles_x + tx;
            isect_ids.data[slot] = g;
            slot++;
        }
    }
}
