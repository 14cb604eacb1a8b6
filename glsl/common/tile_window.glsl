// Where an invocation of a per-tile kernel stands: its pixel, and the window of its tile's
// depth-sorted list that this dispatch walks. The includer declares `tile_ranges` (uvec2
// start/end per tile) first; workgroups are 16x16 tiles laid out as (tiles_x, tiles_y).
#ifndef TILE_WINDOW_GLSL
#define TILE_WINDOW_GLSL

#extension GL_KHR_shader_subgroup_basic : require

struct TileWindow {
    uint t;     // lane-order index in the tile
    uint px;
    uint py;
    uint pix;   // py * width + px
    bool inside;
    uint len;   // entries in the tile's list
    uint start; // this window's first entry (absolute)
    uint end;   // one past its last entry
    bool last;  // the window reaches the end of the list
};

TileWindow tile_window(uint width, uint height, uint tiles_x, uint window_start, uint window_len) {
    TileWindow w;
    w.t = gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
    w.px = gl_WorkGroupID.x * TILE_SIZE + w.t % TILE_SIZE;
    w.py = gl_WorkGroupID.y * TILE_SIZE + w.t / TILE_SIZE;
    w.inside = w.px < width && w.py < height;
    w.pix = w.py * width + w.px;
    uvec2 range = tile_ranges.data[gl_WorkGroupID.y * tiles_x + gl_WorkGroupID.x];
    w.len = range.y - range.x;
    w.start = range.x + min(window_start, w.len);
    w.end = range.x + min(w.len, window_start + window_len);
    w.last = window_start + window_len >= w.len;
    return w;
}

#endif
