// Push constants of forward blending (blend_*.comp) and its backward (blend_backward*.comp):
// one per-tile pass over one window of each tile's list and one chunk of semantic channels.
#ifndef BLEND_PARAMS_GLSL
#define BLEND_PARAMS_GLSL

layout(push_constant) uniform BlendParams {
    uint width;
    uint height;
    uint tiles_x;
    uint channels;     // semantic channels in all (0: RGB only)
    uint window_start; // first entry of each tile's list this dispatch walks
    uint window_len;   // entries it walks at most
    uint chunk_base;   // first semantic channel of this dispatch
    uint write_rgb;    // forward only: 1 in the chunk that writes RGB, alpha, depth and T
    vec3 background;
    uint tile_row_base; // forward only: first tile row of this dispatch's band
} pc;

#endif
