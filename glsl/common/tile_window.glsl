// Where an invocation of a per-tile kernel stands: its pixel, and the window of its tile's
// depth-sorted list that this dispatch walks. The includer declares `tile_ranges` (uvec2
// start/end per tile) first; workgroups are 16x16 tiles laid out as (tiles_x, tiles_y).
#ifndef TILE_WINDOW_GLSL
#define TILE_WINDOW_GLSL

#extension GL_KHR_shader_subgroup_basic : require

// Pixels an invocation takes. On a GPU one (the default): a tile is a workgroup of
// TILE_PIXELS invocations. A CPU driver (lavapipe) runs a workgroup as SIMD vectors and
// reads shared memory and storage buffers one lane at a time, so each step of a tile's list
// costs a read per lane; an invocation that takes PIXELS of the tile's pixels (pixel
// lane + q * LANES for q < PIXELS) reads each step once for all of them: the `*_wide`
// kernels, which the host picks on CPU devices (src/gpu/caps.rs, `cpu_forms`).
#ifndef PIXELS
#define PIXELS 1
#endif
#define LANES (TILE_PIXELS / PIXELS)

// The invocation's index in the workgroup, in lane order.
uint tile_lane() {
    return gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
}

// The q-th (q < PIXELS) of the slots the invocation takes among TILE_PIXELS (the tile's
// pixels, a batch's entries): its lane, then one workgroup's width further each time.
uint invocation_slot(uint q) {
    return tile_lane() + q * LANES;
}

struct TileWindow {
    uint t;     // lane-order index in the tile
    uint px;
    uint py;
    uint pix;   // (py - band's first pixel row) * width + px: see tile_window_in_band
    bool inside;
    uint len;   // entries in the tile's list
    uint start; // this window's first entry (absolute)
    uint end;   // one past its last entry
    bool last;  // the window reaches the end of the list
};

// A dispatch may cover a band of tile rows starting at `tile_row_base` (an image whose
// per-pixel buffers pass one binding is walked band by band): workgroup y counts from the
// band's first row, and per-pixel buffers are bound from the band's first pixel, so `pix`
// counts from there too. `t` is the pixel's index in the tile, in lane order.
TileWindow tile_window_of_pixel(uint width, uint height, uint tiles_x, uint window_start,
                                uint window_len, uint tile_row_base, uint t) {
    TileWindow w;
    uint tile_y = gl_WorkGroupID.y + tile_row_base;
    w.t = t;
    w.px = gl_WorkGroupID.x * TILE_SIZE + w.t % TILE_SIZE;
    w.py = tile_y * TILE_SIZE + w.t / TILE_SIZE;
    w.inside = w.px < width && w.py < height;
    w.pix = (w.py - tile_row_base * TILE_SIZE) * width + w.px;
    uvec2 range = tile_ranges.data[tile_y * tiles_x + gl_WorkGroupID.x];
    w.len = range.y - range.x;
    w.start = range.x + min(window_start, w.len);
    w.end = range.x + min(w.len, window_start + window_len);
    w.last = window_start + window_len >= w.len;
    return w;
}

// The window of the invocation's own pixel (kernels of one pixel an invocation).
TileWindow tile_window_in_band(uint width, uint height, uint tiles_x, uint window_start,
                               uint window_len, uint tile_row_base) {
    uint t = tile_lane();
    return tile_window_of_pixel(width, height, tiles_x, window_start, window_len, tile_row_base, t);
}

// The windows of the invocation's PIXELS pixels, pixel invocation_slot(q) for q < PIXELS
// (one window of the tile's list: every pixel's start, end and len are the same).
void tile_windows(out TileWindow tw[PIXELS], uint width, uint height, uint tiles_x,
                  uint window_start, uint window_len, uint tile_row_base) {
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        tw[q] = tile_window_of_pixel(width, height, tiles_x, window_start, window_len,
                                     tile_row_base, invocation_slot(q));
    }
}

// The whole image in one dispatch.
TileWindow tile_window(uint width, uint height, uint tiles_x, uint window_start, uint window_len) {
    return tile_window_in_band(width, height, tiles_x, window_start, window_len, 0);
}

#endif
