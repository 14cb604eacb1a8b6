// What both forms of emission share (emit.comp, emit_wide.comp): their push constants,
// the arrays they read by address, the pairs they write, and the status words the last
// visible Gaussian's invocation writes.
#ifndef EMIT_COMMON_GLSL
#define EMIT_COMMON_GLSL

layout(push_constant) uniform EmitParams {
    // By address (addressed_arrays.glsl): per Gaussian its tile rectangle, per visible
    // Gaussian in depth order its id and first slot (V + 1).
    uvec2 tile_rects_addr;
    uvec2 depth_ids_addr;
    uvec2 isect_offsets_addr;
    uint tiles_x;
    uint capacity;
    uint row_begin; // first tile row binned (see gather_touched.comp)
    uint row_end;   // one past the last
} pc;

#include "addressed_arrays.glsl"
#define tile_rects UVec4Array(pc.tile_rects_addr)
#define depth_ids UintArray(pc.depth_ids_addr)
#define isect_offsets UintArray(pc.isect_offsets_addr)

layout(set = 0, binding = 0) buffer StatusBuf { uint data[]; } status;
layout(set = 0, binding = 4) writeonly buffer KeysBuf { uint data[]; } isect_keys;
layout(set = 0, binding = 5) writeonly buffer ValsBuf { uint data[]; } isect_ids;

// Writes the status words once the last Gaussian's offset (the total) is known.
void write_totals(uint v) {
    uint needed = isect_offsets.data[v];
    uint kept = min(needed, pc.capacity);
    status.data[ST_ISECT] = kept;
    status.data[ST_ISECT_NEEDED] = needed;
    status.data[ST_OVERFLOW] = needed > pc.capacity ? 1 : 0;
    status.data[ST_ARGS_ISECT + 0] = (kept + 255) / 256;
    status.data[ST_ARGS_ISECT + 1] = 1;
    status.data[ST_ARGS_ISECT + 2] = 1;
}

#endif
