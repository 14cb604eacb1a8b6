#version 460
// Tile counts of the visible Gaussians in depth order (and a trailing zero), for the scan
// that gives each Gaussian its first intersection slot: the tiles of its rectangle within
// the rows this binning covers (a view whose lists pass one binding is binned in bands of
// tile rows).
#include "raster_common.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform GatherTouchedParams {
    // By address (addressed_arrays.glsl): per Gaussian its tile rectangle, per visible
    // Gaussian in depth order its id and (written) its tile count.
    uvec2 tile_rects_addr;
    uvec2 depth_ids_addr;
    uvec2 sorted_touched_addr;
    uint row_begin; // first tile row binned
    uint row_end;   // one past the last
} pc;

#include "addressed_arrays.glsl"
#define tile_rects UVec4Array(pc.tile_rects_addr)
#define depth_ids UintArray(pc.depth_ids_addr)
#define sorted_touched UintArrayRW(pc.sorted_touched_addr)

layout(set = 0, binding = 0) readonly buffer StatusBuf { uint data[]; } status;

void main() {
    uint j = gl_GlobalInvocationID.x;
    uint v = status.data[ST_VISIBLE];
    if (j < v) {
        uvec4 r = tile_rects.data[depth_ids.data[j]];
        uint y0 = max(r.y, pc.row_begin), y1 = min(r.w, pc.row_end);
        sorted_touched.data[j] = y1 > y0 ? (r.z - r.x) * (y1 - y0) : 0;
    } else if (j == v) {
        sorted_touched.data[j] = 0;
    }
}
