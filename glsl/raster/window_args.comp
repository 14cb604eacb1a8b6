#version 460
// Indirect dispatch arguments for the later windows of a per-tile pass (src/render/windows.rs).
// A device with a loop cap walks tile lists in windows of window_len entries, one dispatch
// each, and the host records as many windows as the longest list the scene could make
// (every Gaussian in one tile); nearly all of them start past every list's end. A
// workgroup that finds its window empty returns at once, but on a CPU driver each still
// costs its launch (at 1M Gaussians, 30 empty windows took half of a frame's blending).
// One workgroup per band of tile rows finds the band's longest list and writes, for each
// window after the first, the band's tile groups where the window starts inside that list,
// else no workgroups.

layout(local_size_x = 256) in;

layout(push_constant) uniform WindowArgsParams {
    uint tiles_x;
    uint first_row;  // the first tile row of the lists (of their band, if binned in bands)
    uint rows;       // tile rows the pass covers, from first_row
    uint band_rows;  // tile rows of each band of the pass but the last
    uint window_len;
    uint windows;    // windows of the pass; the first is dispatched directly
} pc;

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
layout(set = 0, binding = 1) writeonly buffer ArgsBuf { uint data[]; } args;

shared uint longest;

void main() {
    uint band = gl_WorkGroupID.x;
    uint bands = gl_NumWorkGroups.x;
    uint row0 = pc.first_row + band * pc.band_rows;
    uint band_rows = min(pc.band_rows, pc.rows - band * pc.band_rows);
    if (gl_LocalInvocationIndex == 0) {
        longest = 0;
    }
    barrier();
    uint tiles = band_rows * pc.tiles_x;
    uint mine = 0;
    for (uint t = gl_LocalInvocationIndex; t < tiles; t += gl_WorkGroupSize.x) {
        uvec2 range = tile_ranges.data[row0 * pc.tiles_x + t];
        mine = max(mine, range.y - range.x);
    }
    atomicMax(longest, mine);
    barrier();
    for (uint w = 1 + gl_LocalInvocationIndex; w < pc.windows; w += gl_WorkGroupSize.x) {
        bool live = longest > w * pc.window_len;
        uint at = 3 * ((w - 1) * bands + band);
        args.data[at] = live ? pc.tiles_x : 0;
        args.data[at + 1] = live ? band_rows : 0;
        args.data[at + 2] = live ? 1 : 0;
    }
}
