// Backward of forward blending (blend_body.glsl) for one 16x16 tile per workgroup.
// Included by the blend_backward*.comp kernels after grad_add_float.glsl or
// grad_add_cas.glsl, which define grad_add(index, value) and sem_grad_add(index, value)
// and bind their buffers. With SEM_ONLY (the *_sem_only
// variants, for training the logits with geometry frozen) only the semantic vectors'
// gradient w_i * dL/dsem is computed: no alpha gradient, no carried sums.
//
// Per pixel, contributors are walked back to front from the last blended entry, starting
// from the saved final T and recovering T_i = T_{i+1} / (1 - alpha_i). The upstream
// gradients are dL/d(rgb), dL/d(accumulated alpha) and dL/d(normalized semantics); the
// Gaussian Semantics Eq. 2 normalization (sem / (1 - T_final)) is undone per pixel first, which turns it into
// a gradient on the raw blend plus one on T_final. Each Gaussian's gradient is summed
// across the subgroup before the atomics (its channels by one reduce-scatter), and steps
// where no lane of a subgroup contributes are skipped with a vote.
//
// Windows: like the forward, one dispatch walks at most window_len entries of a tile's
// list; windows run from the last to the first, carrying T and the sums of what lies
// behind (S_rgb, S_sem) per pixel. Semantic chunks: a dispatch handles SEM_CHUNK channels
// (chunk_base); only chunk 0 adds the RGB and T_final terms and the color gradient. Every
// chunk adds its channels' share of the alpha gradient, so the sum over chunks is exact.
//
// Each invocation takes PIXELS of the tile's pixels (tile_window.glsl: one on a GPU, more
// in the `*_wide` kernels for CPU drivers). A step's values are summed over the
// invocation's pixels first, then over the subgroup, so a CPU driver pays one
// reduce-scatter and one read of the step's shared data for all of them.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "raster_common.glsl"
#include "subgroup_reduce_scatter.glsl"
#if SEM_CHUNK != 16
#error "a chunk's channels are summed by reduce_scatter16"
#endif

#define BATCH TILE_PIXELS
// Screen-space gradient per Gaussian (grad2d, GRAD2D_STRIDE floats, shared_constants.txt):
// mean2d x y, conic A B C, opacity, color r g b.
// Values reduced per (tile, Gaussian) step: the 10 screen-space ones, then the channels.
#define STEP_VALUES (GRAD2D_STRIDE + SEM_CHUNK)
// Carried per pixel between windows: T, S_rgb (3), S_sem (SEM_CHUNK).
#define CARRY_STRIDE BACKWARD_CARRY_STRIDE

#include "blend_params.glsl"

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
#ifdef WIDE
// The `*_wide` kernels: 4 pixels an invocation. On lavapipe more pixels ran faster (the
// office at 640x480, 12 channels: 6.1 s narrow, 2.5 s at 4, 1.7-2.0 s at 8, 1.3-1.6 s at
// 16) but compiled far slower on a cold shader cache, as on a fresh machine (+5 s at 4,
// +23 s at 8, +69 s at 16 for the float variant; docs/architecture.md).
#define PIXELS 4
#endif
#include "tile_window.glsl"
layout(local_size_x = LANES) in;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 7) readonly buffer FinalTBuf { float data[]; } final_t;
layout(set = 0, binding = 8) readonly buffer LastBuf { uint data[]; } last_entry;
layout(set = 0, binding = 9) readonly buffer CountBuf { uint data[]; } n_contrib;
#ifndef SEM_ONLY
// What only the alpha, colour and screen-space gradients read: declared for those variants
// alone, so the semantic-only ones bind nothing they never read.
layout(set = 0, binding = 10) readonly buffer SemNormBuf { float data[]; } sem_norm;
layout(set = 0, binding = 11) readonly buffer VRgbBuf { float data[]; } v_rgb;
layout(set = 0, binding = 12) readonly buffer VAlphaBuf { float data[]; } v_alpha;
#endif
layout(set = 0, binding = 13) readonly buffer VSemNormBuf { float data[]; } v_sem_norm;
layout(set = 0, binding = 14) buffer CarryBuf { float data[]; } carry;

shared vec4 s_xy_depth_opacity[BATCH];
shared vec2 s_frac[BATCH];
shared vec4 s_conic[BATCH];
shared vec4 s_color[BATCH];
shared uint s_id[BATCH];
shared float s_sem[BATCH * SEM_CHUNK];
shared uint s_bound; // one past the furthest entry any pixel of the tile blended

#if PIXELS > 1
// The step's color and channels, read once for all the invocation's pixels (each read
// of shared memory is a loop over the lanes on a CPU driver).
vec3 step_color;
float step_sem[SEM_CHUNK];
#define STEP_COLOR step_color
#define STEP_SEM(k) step_sem[k]
#else
// Read only where the pixel takes the step.
#define STEP_COLOR s_color[j].rgb
#define STEP_SEM(k) s_sem[j * SEM_CHUNK + k]
#endif

// One pixel's state: what it blended, its upstream gradients, and the transmittance and
// sums of what lies behind the step (carried between windows in `carry`).
struct PixelGrad {
    TileWindow tw;
    vec2 pixel;
    uint bound;      // one past the last list entry the pixel blended
    float t_final;
    vec3 v_col;
    float v_tfinal;  // dL/dT_final from the outputs that read it directly
    float v_sem[SEM_CHUNK];
    float T;
    vec3 s_rgb;
    float s_sem_acc[SEM_CHUNK];
};

// The pixel's upstream gradients, and its state from the last window of the list or
// carried from the one after.
PixelGrad pixel_grad_start(TileWindow tw, bool with_rgb, uint channels, uint chunk_base) {
    PixelGrad p;
    p.tw = tw;
    p.pixel = vec2(tw.px, tw.py);
    p.bound = 0;
    p.t_final = 1.0;
    p.v_col = vec3(0.0);
    p.v_tfinal = 0.0;
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        p.v_sem[k] = 0.0;
        p.s_sem_acc[k] = 0.0;
    }
    uint pix = tw.pix;
    if (tw.inside && n_contrib.data[pix] > 0) {
        p.bound = last_entry.data[pix] + 1;
        p.t_final = final_t.data[pix];
        float covered = 1.0 - p.t_final;
#ifndef SEM_ONLY
        if (with_rgb) {
            p.v_col = vec3(v_rgb.data[3 * pix], v_rgb.data[3 * pix + 1], v_rgb.data[3 * pix + 2]);
            // rgb = sum + T_final * background; accumulated alpha = 1 - T_final.
            p.v_tfinal = dot(p.v_col, pc.background) - v_alpha.data[pix];
        }
#endif
        // Gaussian Semantics Eq. 2: sem_norm = sem / (1 - T_final), so dL/dsem = v / (1 - T_final) and
        // dL/dT_final += sum_k v_k sem_norm_k / (1 - T_final).
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            uint c = chunk_base + k;
            if (c < channels && covered > 0.0) {
                float v = v_sem_norm.data[pix * channels + c];
                p.v_sem[k] = v / covered;
#ifndef SEM_ONLY
                p.v_tfinal += v * sem_norm.data[pix * channels + c] / covered;
#endif
            }
        }
    }
    p.T = p.t_final;
    p.s_rgb = vec3(0.0);
    uint c0 = pix * CARRY_STRIDE;
    if (!tw.last && tw.inside) {
        p.T = carry.data[c0];
        p.s_rgb = vec3(carry.data[c0 + 1], carry.data[c0 + 2], carry.data[c0 + 3]);
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            p.s_sem_acc[k] = carry.data[c0 + 4 + k];
        }
    }
    return p;
}

// Loads entry `idx` of the tile's list into batch slot `slot`.
void load_entry(uint idx, uint slot, uint channels, uint chunk_base) {
    uint g = isect_ids.data[idx];
    s_id[slot] = g;
    s_xy_depth_opacity[slot] = xy_depth_opacity.data[g];
    s_frac[slot] = xy_frac.data[g];
    s_conic[slot] = conics.data[g];
#ifndef SEM_ONLY
    s_color[slot] = colors.data[g];
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        uint c = chunk_base + k;
        s_sem[slot * SEM_CHUNK + k] = c < channels ? sem_in.data[g * channels + c] : 0.0;
    }
#endif
}

// How a step's Gaussian falls on one pixel: whether the pixel blended it, and its alpha.
struct StepHit {
    bool live;
    float alpha;
    float gauss;
    vec2 d;
};

StepHit step_hit(uint bound, vec2 pixel, uint entry, vec4 g, vec3 con, vec2 frac) {
    StepHit h;
    h.live = entry < bound;
    h.alpha = 0.0;
    h.gauss = 0.0;
    h.d = vec2(0.0);
    if (h.live) {
        h.d = pixel_offset(g.xy, frac, pixel);
        float sigma = conic_sigma(con, h.d);
        h.gauss = exp(-sigma);
        h.alpha = min(ALPHA_MAX, g.w * h.gauss);
        h.live = sigma >= 0.0 && h.alpha >= ALPHA_MIN;
    }
    return h;
}

// Adds a live step's values at pixel `p` to `vals` and moves the pixel's state in front of
// the step (batch slot `j`).
void step_grads(inout PixelGrad p, StepHit h, uint j, vec4 g, vec3 con, bool with_rgb,
                inout float vals[STEP_VALUES]) {
    float one_minus = 1.0 - h.alpha;
    float t_i = p.T / one_minus; // transmittance in front of this Gaussian
    float w = h.alpha * t_i;
#ifdef SEM_ONLY
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        vals[GRAD2D_STRIDE + k] += w * p.v_sem[k];
    }
#else
    // dL/dalpha: its own weight, the dimming of everything behind it, and T_final.
    float v_a = -p.v_tfinal * p.t_final / one_minus;
    if (with_rgb) {
        vec3 c = STEP_COLOR;
        v_a += dot(p.v_col, c * t_i - p.s_rgb / one_minus);
        p.s_rgb += w * c;
        vals[6] += w * p.v_col.r;
        vals[7] += w * p.v_col.g;
        vals[8] += w * p.v_col.b;
    }
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        float s = STEP_SEM(k);
        v_a += p.v_sem[k] * (s * t_i - p.s_sem_acc[k] / one_minus);
        p.s_sem_acc[k] += w * s;
        vals[GRAD2D_STRIDE + k] += w * p.v_sem[k];
    }
    // alpha = min(0.999, o exp(-sigma)): no gradient through the clamp.
    if (g.w * h.gauss <= ALPHA_MAX) {
        vec2 d = h.d;
        float v_sigma = -v_a * h.alpha;
        vals[0] += v_sigma * (con.x * d.x + con.y * d.y);
        vals[1] += v_sigma * (con.z * d.y + con.y * d.x);
        vals[2] += v_sigma * 0.5 * d.x * d.x;
        vals[3] += v_sigma * d.x * d.y;
        vals[4] += v_sigma * 0.5 * d.y * d.y;
        vals[5] += v_a * h.gauss;
    }
#endif
    p.T = t_i;
}

// Sums a step's values over the subgroup and adds each sum to Gaussian `gid`'s gradients
// by one atomic (subgroup-uniform control flow).
void add_step(uint gid, float vals[STEP_VALUES], uint channels, uint chunk_base) {
    uint lane = gl_SubgroupInvocationID;
#ifndef SEM_ONLY
    // Screen-space values (padded to 16): one reduce-scatter leaves each sum in one
    // lane, which does its atomic.
    float geo_sums[16];
    [[unroll]] for (uint k = 0; k < 16; k++) {
        geo_sums[k] = k < GRAD2D_STRIDE ? vals[k] : 0.0;
    }
    reduce_scatter16(geo_sums);
    [[unroll]] for (uint i = 0; i < 4; i++) {
        uint k = reduce_scatter_index(lane, i);
        if (k < GRAD2D_STRIDE && geo_sums[i] != 0.0) {
            grad_add(gid * GRAD2D_STRIDE + k, geo_sums[i]);
        }
    }
#endif
    // The chunk's channels: one reduce-scatter leaves each channel's sum in one
    // lane, which does its atomic (16 shuffles at 32 lanes instead of 16 sums of 5).
    if (chunk_base < channels) { // uniform: RGB-only frames have no channels
        float sem_sums[SEM_CHUNK];
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            sem_sums[k] = vals[GRAD2D_STRIDE + k];
        }
        reduce_scatter16(sem_sums);
        [[unroll]] for (uint i = 0; i < 4; i++) {
            uint k = reduce_scatter_index(lane, i);
            uint c = chunk_base + k;
            if (k < SEM_CHUNK && c < channels && sem_sums[i] != 0.0) {
                sem_grad_add(gid * channels + c, sem_sums[i]);
            }
        }
    }
}

// Writes a pixel's state for the window before this one.
void pixel_grad_carry(PixelGrad p) {
    uint c0 = p.tw.pix * CARRY_STRIDE;
    carry.data[c0] = p.T;
    carry.data[c0 + 1] = p.s_rgb.r;
    carry.data[c0 + 2] = p.s_rgb.g;
    carry.data[c0 + 3] = p.s_rgb.b;
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        carry.data[c0 + 4 + k] = p.s_sem_acc[k];
    }
}

// One past the furthest entry any pixel of the tile blended (every invocation calls it).
uint tile_bound(PixelGrad px[PIXELS]) {
    if (tile_lane() == 0) {
        s_bound = 0;
    }
    barrier();
    uint bound = 0;
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        bound = max(bound, px[q].bound);
    }
    uint sg_bound = subgroupMax(bound);
    if (subgroupElect()) {
        atomicMax(s_bound, sg_bound);
    }
    barrier();
    return s_bound;
}

void main() {
    uint width = pc.width, height = pc.height, channels = pc.channels;
    uint window_start = pc.window_start, window_len = pc.window_len, chunk_base = pc.chunk_base;
#ifdef SEM_ONLY
    bool with_rgb = false; // only the semantic vectors' gradient (geometry frozen)
#else
    bool with_rgb = chunk_base == 0;
#endif
    TileWindow tw[PIXELS];
    tile_windows(tw, width, height, pc.tiles_x, window_start, window_len, pc.tile_row_base);
    if (window_start > 0 && window_start >= tw[0].len) {
        return; // this tile's list ends before the window
    }
    PixelGrad px[PIXELS];
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        px[q] = pixel_grad_start(tw[q], with_rgb, channels, chunk_base);
    }
    uint start = tw[0].start;
    uint hi = min(tw[0].end, tile_bound(px));

    // Batches back to front: [b0, b1) with b1 descending.
    for (uint b1 = hi; b1 > start; b1 -= min(BATCH, b1 - start)) {
        uint count = min(BATCH, b1 - start);
        uint b0 = b1 - count;
        [[unroll]] for (uint q = 0; q < PIXELS; q++) {
            uint slot = invocation_slot(q);
            if (slot < count) {
                load_entry(b0 + slot, slot, channels, chunk_base);
            }
        }
        barrier();
        for (uint jj = count; jj > 0; jj--) {
            uint j = jj - 1;
            vec4 g = s_xy_depth_opacity[j];
            vec3 con = s_conic[j].xyz;
            vec2 frac = s_frac[j];
            StepHit hit[PIXELS];
            bool any_live = false;
            [[unroll]] for (uint q = 0; q < PIXELS; q++) {
                hit[q] = step_hit(px[q].bound, px[q].pixel, b0 + j, g, con, frac);
                any_live = any_live || hit[q].live;
            }
            if (!subgroupAny(any_live)) {
                continue;
            }
#if PIXELS > 1 && !defined(SEM_ONLY)
            step_color = s_color[j].rgb;
            [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
                step_sem[k] = s_sem[j * SEM_CHUNK + k];
            }
#endif
            float vals[STEP_VALUES];
            [[unroll]] for (uint k = 0; k < STEP_VALUES; k++) {
                vals[k] = 0.0;
            }
            [[unroll]] for (uint q = 0; q < PIXELS; q++) {
                if (hit[q].live) {
                    step_grads(px[q], hit[q], j, g, con, with_rgb, vals);
                }
            }
            add_step(s_id[j], vals, channels, chunk_base);
        }
        barrier(); // the next batch overwrites the shared arrays
    }

    if (window_start > 0) {
        [[unroll]] for (uint q = 0; q < PIXELS; q++) {
            if (tw[q].inside) {
                pixel_grad_carry(px[q]);
            }
        }
    }
}
