// Forward blending of one 16x16 tile per workgroup (included by blend_rgb.comp with
// CHUNK_CHANNELS 0, blend_sem.comp with CHUNK_CHANNELS 16, blend_label.comp, and
// blend_median_depth.comp with MEDIAN_DEPTH: only each pixel's median and opaque depths;
// each also as a `*_wide` kernel with PIXELS set).
//
// Each workgroup loads its tile's Gaussians into shared memory in batches; a pixel stops at
// the transmittance threshold, and the tile stops once every pixel is done (subgroup vote,
// then a workgroup count). One dispatch covers a window of at most `window_len` entries of
// each tile's list: per-pixel state (T, accumulators) is carried in a buffer between
// windows, so no invocation comes near lavapipe's 65,535-iteration loop cap. Semantic
// channels are processed CHUNK_CHANNELS at a time (chunk_base), C being a run-time value.
// Each invocation blends PIXELS of the tile's pixels (tile_window.glsl: one on a GPU, more
// in the `*_wide` kernels for CPU drivers), each in the same order as alone.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#include "raster_common.glsl"
#include "tile_vote.glsl"

#define BATCH TILE_PIXELS
// Carried state per pixel: T, r, g, b, depth sum, contributors, last, done, then sems.
#define CARRY_STRIDE (BLEND_CARRY_BASE + CHUNK_CHANNELS)

#include "blend_params.glsl"

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
#include "tile_window.glsl"
layout(local_size_x = LANES) in;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 5) buffer CarryBuf { float data[]; } carry;
layout(set = 0, binding = 6) writeonly buffer RgbBuf { float data[]; } out_rgb;
#if defined(MEDIAN_DEPTH)
layout(set = 0, binding = 7) writeonly buffer OpaqueDepthBuf { float data[]; } out_opaque_depth;
#else
layout(set = 0, binding = 7) writeonly buffer AlphaBuf { float data[]; } out_alpha;
#endif
layout(set = 0, binding = 8) writeonly buffer DepthBuf { float data[]; } out_depth;
layout(set = 0, binding = 9) writeonly buffer FinalTBuf { float data[]; } out_final_t;
layout(set = 0, binding = 10) writeonly buffer LastBuf { uint data[]; } out_last;
layout(set = 0, binding = 11) writeonly buffer CountBuf { uint data[]; } out_n_contrib;
#if defined(LABEL_ARGMAX)
// Label rendering: each Gaussian blends the one-hot vector of its class (NO_LABEL: zeros),
// and each pixel keeps only the running argmax over the chunks of classes, so C classes
// cost C / CHUNK_CHANNELS passes but no per-pixel C-vector.
#define classes UintArray(pc.sem_in_addr)
layout(set = 0, binding = 13) buffer BestBuf { uvec2 data[]; } label_best; // (value bits, class)
shared float s_sem[BATCH * CHUNK_CHANNELS];
#elif CHUNK_CHANNELS > 0
layout(set = 0, binding = 13) writeonly buffer SemOutBuf { float data[]; } out_sem;
layout(set = 0, binding = 14) writeonly buffer SemNormBuf { float data[]; } out_sem_norm;
shared float s_sem[BATCH * CHUNK_CHANNELS];
#endif

shared vec4 s_xy_depth_opacity[BATCH]; // floor(mean2d) depth opacity
shared vec2 s_frac[BATCH];             // mean2d - floor(mean2d)
shared vec4 s_conic[BATCH];
shared vec4 s_color[BATCH];

#if PIXELS > 1
// The step's color and channels, read once for all the invocation's pixels (each read
// of shared memory is a loop over the lanes on a CPU driver).
vec3 step_color;
float step_sem[CHUNK_CHANNELS > 0 ? CHUNK_CHANNELS : 1];
#define STEP_COLOR step_color
#define STEP_SEM(k) step_sem[k]
#else
// Read only where the pixel takes the step.
#define STEP_COLOR s_color[j].rgb
#define STEP_SEM(k) s_sem[j * CHUNK_CHANNELS + k]
#endif

// One pixel's blending state, carried between windows in `carry`.
struct Pixel {
    float T;
    vec3 rgb;
    float depth_sum; // MEDIAN_DEPTH: the median depth once found
    uint n_contrib;
    uint last;
    bool done;
#if CHUNK_CHANNELS > 0
    float sem[CHUNK_CHANNELS];
#endif
};

Pixel pixel_start(TileWindow tw, uint window_start) {
    Pixel p;
    p.T = 1.0;
    p.rgb = vec3(0.0);
    p.depth_sum = 0.0;
    p.n_contrib = 0;
    p.last = 0;
    p.done = !tw.inside;
#if CHUNK_CHANNELS > 0
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        p.sem[k] = 0.0;
    }
#endif
    if (window_start > 0 && tw.inside) {
        uint c0 = tw.pix * CARRY_STRIDE;
        p.T = carry.data[c0];
        p.rgb = vec3(carry.data[c0 + 1], carry.data[c0 + 2], carry.data[c0 + 3]);
        p.depth_sum = carry.data[c0 + 4];
        p.n_contrib = floatBitsToUint(carry.data[c0 + 5]);
        p.last = floatBitsToUint(carry.data[c0 + 6]);
        p.done = carry.data[c0 + 7] != 0.0;
#if CHUNK_CHANNELS > 0
        [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
            p.sem[k] = carry.data[c0 + BLEND_CARRY_BASE + k];
        }
#endif
    }
    return p;
}

// Loads entry `idx` of the tile's list into batch slot `slot`.
void load_entry(uint idx, uint slot, uint channels, uint chunk_base) {
    uint g = isect_ids.data[idx];
    s_xy_depth_opacity[slot] = xy_depth_opacity.data[g];
    s_frac[slot] = xy_frac.data[g];
    s_conic[slot] = conics.data[g];
#if !defined(MEDIAN_DEPTH)
    s_color[slot] = colors.data[g];
#endif
#if defined(LABEL_ARGMAX)
    uint cls = classes.data[g];
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        s_sem[slot * CHUNK_CHANNELS + k] = cls == chunk_base + k ? 1.0 : 0.0;
    }
#elif CHUNK_CHANNELS > 0
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        uint c = chunk_base + k;
        s_sem[slot * CHUNK_CHANNELS + k] = c < channels ? sem_in.data[g * channels + c] : 0.0;
    }
#endif
}

// Blends a step of opacity `alpha` (at least ALPHA_MIN) into pixel `p`.
void blend_alpha(inout Pixel p, uint j, uint entry, vec4 g, float alpha, bool write_rgb) {
    float next_t = p.T * (1.0 - alpha);
#if defined(MEDIAN_DEPTH)
    // The Gaussian that takes the pixel's transmittance below one half: its depth is the
    // pixel's median depth (held in depth_sum, the carried state's depth slot). Then the
    // one that takes it below OPAQUE_T: its depth is the opaque depth (held in rgb.r, the
    // carried red slot), behind which the pixel hides everything; nothing further is
    // needed.
    if (p.T >= MEDIAN_T && next_t < MEDIAN_T) {
        p.depth_sum = g.z;
    }
    p.T = next_t;
    if (next_t < OPAQUE_T) {
        p.rgb.r = g.z;
        p.done = true;
    }
#else
    if (next_t <= T_MIN) {
        p.done = true;
    } else {
        float weight = alpha * p.T;
        if (write_rgb) {
            p.rgb += weight * STEP_COLOR;
            p.depth_sum += weight * g.z;
        }
#if CHUNK_CHANNELS > 0
        [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
            p.sem[k] += weight * STEP_SEM(k);
        }
#endif
        p.T = next_t;
        p.n_contrib++;
        p.last = entry;
    }
#endif
}

// Blends batch slot `j` (list entry `entry`) into pixel `p` at `pixel`, unless it is done;
// returns whether it is done after the step. Written with one exit: with an early return
// for each skip (which glslang inlines as a switch) and the loop asking every pixel's
// state before each step, the same blend rendered a room 8-14% slower on an H200
// (docs/gpu.md, 2026-11-30). With one pixel an invocation the batch's loop has stopped
// before a done pixel's step, so the test is left to the kernels of several.
bool blend_step(inout Pixel p, vec2 pixel, uint j, uint entry, vec4 g, vec3 con, vec2 frac,
                bool write_rgb) {
#if PIXELS > 1
    if (!p.done)
#endif
    {
        vec2 d = pixel_offset(g.xy, frac, pixel);
        float sigma = conic_sigma(con, d);
        if (sigma >= 0.0) {
            float alpha = min(ALPHA_MAX, g.w * exp(-sigma));
            if (alpha >= ALPHA_MIN) {
                blend_alpha(p, j, entry, g, alpha, write_rgb);
            }
        }
    }
    return p.done;
}

bool all_done(Pixel px[PIXELS]) {
    bool done = true;
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        done = done && px[q].done;
    }
    return done;
}

// Writes a pixel's state for the next window, or its outputs after the last.
void pixel_finish(Pixel p, TileWindow tw, bool write_rgb, uint channels, uint chunk_base) {
    uint pix = tw.pix;
    if (!tw.last) {
        uint c0 = pix * CARRY_STRIDE;
        carry.data[c0] = p.T;
        carry.data[c0 + 1] = p.rgb.r;
        carry.data[c0 + 2] = p.rgb.g;
        carry.data[c0 + 3] = p.rgb.b;
        carry.data[c0 + 4] = p.depth_sum;
        carry.data[c0 + 5] = uintBitsToFloat(p.n_contrib);
        carry.data[c0 + 6] = uintBitsToFloat(p.last);
        carry.data[c0 + 7] = p.done ? 1.0 : 0.0;
#if CHUNK_CHANNELS > 0
        [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
            carry.data[c0 + BLEND_CARRY_BASE + k] = p.sem[k];
        }
#endif
        return;
    }
#if defined(MEDIAN_DEPTH)
    // 0 where the transmittance never fell below one half (no surface to test against),
    // or below OPAQUE_T (nothing hidden).
    out_depth.data[pix] = p.T < MEDIAN_T ? p.depth_sum : 0.0;
    out_opaque_depth.data[pix] = p.T < OPAQUE_T ? p.rgb.r : 0.0;
#else
    float acc_alpha = 1.0 - p.T;
    if (write_rgb) {
        vec3 c = p.rgb + p.T * pc.background;
        out_rgb.data[3 * pix] = c.r;
        out_rgb.data[3 * pix + 1] = c.g;
        out_rgb.data[3 * pix + 2] = c.b;
        out_alpha.data[pix] = acc_alpha;
        out_depth.data[pix] = acc_alpha > 0.0 ? p.depth_sum / acc_alpha : 0.0;
        out_final_t.data[pix] = p.T;
        out_last.data[pix] = p.last;
        out_n_contrib.data[pix] = p.n_contrib;
    }
#if defined(LABEL_ARGMAX)
    // The largest normalized value so far, later classes winning ties (as a host argmax
    // over the whole vector taking the last maximum would).
    uvec2 best = chunk_base == 0 ? uvec2(floatBitsToUint(0.0), NO_LABEL) : label_best.data[pix];
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        uint c = chunk_base + k;
        float v = acc_alpha > 0.0 ? p.sem[k] / acc_alpha : 0.0;
        if (c < channels && (best.y == NO_LABEL || v >= uintBitsToFloat(best.x))) {
            best = uvec2(floatBitsToUint(v), c);
        }
    }
    label_best.data[pix] = best;
#elif CHUNK_CHANNELS > 0
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        uint c = chunk_base + k;
        if (c < channels) {
            out_sem.data[pix * channels + c] = p.sem[k];
            out_sem_norm.data[pix * channels + c] = acc_alpha > 0.0 ? p.sem[k] / acc_alpha : 0.0;
        }
    }
#endif
#endif // MEDIAN_DEPTH
}

void main() {
    uint width = pc.width, height = pc.height, channels = pc.channels;
    uint window_start = pc.window_start, window_len = pc.window_len, chunk_base = pc.chunk_base;
    bool write_rgb = pc.write_rgb != 0;
    TileWindow tw[PIXELS];
    tile_windows(tw, width, height, pc.tiles_x, window_start, window_len, pc.tile_row_base);
    // Later windows only continue tiles that are longer; window 0 always writes (background).
    if (window_start > 0 && window_start >= tw[0].len) {
        return;
    }
    Pixel px[PIXELS];
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        px[q] = pixel_start(tw[q], window_start);
    }
    // Converted once, not at every step.
    vec2 pixel[PIXELS];
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        pixel[q] = vec2(tw[q].px, tw[q].py);
    }
    uint start = tw[0].start, end = tw[0].end;

    for (uint b = start; b < end; b += BATCH) {
        // Stop the tile once every pixel is done.
        bool done = all_done(px);
        if (workgroup_all_done(done)) {
            break;
        }
        [[unroll]] for (uint q = 0; q < PIXELS; q++) {
            uint slot = invocation_slot(q);
            if (b + slot < end) {
                load_entry(b + slot, slot, channels, chunk_base);
            }
        }
        barrier();
        // The loop is left by its condition, as the kernel before the per-pixel form was
        // (docs/gpu.md, 2026-11-30: that form blended faster on an H200).
        uint count = min(BATCH, end - b);
        for (uint j = 0; j < count && !done; j++) {
            vec4 g = s_xy_depth_opacity[j];
            vec3 con = s_conic[j].xyz;
            vec2 frac = s_frac[j];
#if PIXELS > 1 && !defined(MEDIAN_DEPTH)
            step_color = s_color[j].rgb;
#endif
#if PIXELS > 1 && CHUNK_CHANNELS > 0
            [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
                step_sem[k] = s_sem[j * CHUNK_CHANNELS + k];
            }
#endif
            done = true;
            [[unroll]] for (uint q = 0; q < PIXELS; q++) {
                done = blend_step(px[q], pixel[q], j, b + j, g, con, frac, write_rgb) && done;
            }
        }
        barrier(); // the next batch overwrites the shared arrays
    }

    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        if (tw[q].inside) {
            pixel_finish(px[q], tw[q], write_rgb, channels, chunk_base);
        }
    }
}
