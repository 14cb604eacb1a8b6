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
    uint tile_row_base; // first tile row of this dispatch's band
    // Addresses of the per-Gaussian arrays (addressed_arrays.glsl).
    uvec2 xy_depth_opacity_addr;
    uvec2 xy_frac_addr;
    uvec2 conics_addr;
    uvec2 colors_addr;
    uvec2 sem_in_addr; // semantic vectors [n][channels], or the class of each Gaussian (labels)
    uvec2 grad2d_addr;   // backward only: screen-space gradient sums
    uvec2 grad_sem_addr; // backward only: semantic gradient sums
} pc;

#include "addressed_arrays.glsl"
#define xy_depth_opacity Vec4Array(pc.xy_depth_opacity_addr)
#define xy_frac Vec2Array(pc.xy_frac_addr)
#define conics Vec4Array(pc.conics_addr)
#define colors Vec4Array(pc.colors_addr)
#define sem_in FloatArray(pc.sem_in_addr)

#endif
