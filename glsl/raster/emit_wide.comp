#version 460
// emit.comp for CPU drivers (the host picks it where it picks every `*_wide` kernel,
// `DeviceCaps::cpu_forms`): one invocation per visible Gaussian writes its own pairs, row
// by row of its tiles within the binned rows, from the first slot its offset gives: the
// same pairs in the same slots as emit.comp's load-balanced walk, without its shared memory
// (which a CPU driver reads one lane at a time) and binary searches. lavapipe's loop cap
// counts every iteration of an invocation, so the host picks this form only where one
// Gaussian's pairs in the band stay under it (`emit_kernel` in src/render/rasterizer.rs).
#include "raster_common.glsl"

layout(local_size_x = 256) in;

#include "emit_common.glsl"

void main() {
    uint j = gl_GlobalInvocationID.x;
    uint v = status.data[ST_VISIBLE];
    if (j == v) {
        write_totals(v);
    }
    if (j >= v) {
        return;
    }
    uint first = isect_offsets.data[j];
    uint next = isect_offsets.data[j + 1];
    // As emit.comp: a 32-bit scan that wrapped is flagged, and the host refuses the frame.
    if (next < first) {
        status.data[ST_ISECT_WRAPPED] = 1;
        return;
    }
    // Past the capacity pairs are dropped (the host grows the lists and runs again).
    uint end = min(next, pc.capacity);
    uint g = depth_ids.data[j];
    uvec4 r = tile_rects.data[g];
    uint slot = first;
    for (uint y = max(r.y, pc.row_begin); y < min(r.w, pc.row_end) && slot < end; y++) {
        for (uint x = r.x; x < r.z && slot < end; x++) {
            isect_keys.data[slot] = y * pc.tiles_x + x;
            isect_ids.data[slot] = g;
            slot++;
        }
    }
}
