// Forward blending of one 16x16 tile per workgroup (included by blend_rgb.comp with
// CHUNK_CHANNELS 0, blend_sem.comp with CHUNK_CHANNELS 16, blend_label.comp, and
// blend_median_depth.comp with MEDIAN_DEPTH: only each pixel's median depth).
//
// Each workgroup loads its tile's Gaussians into shared memory in batches; a pixel stops at
// the transmittance threshold, and the tile stops once every pixel is done (subgroup vote,
// then a workgroup count). One dispatch covers a window of at most `window_len` entries of
// each tile's list: per-pixel state (T, accumulators) is carried in a buffer between
// windows, so no invocation comes near lavapipe's 65,535-iteration loop cap. Semantic
// channels are processed CHUNK_CHANNELS at a time (chunk_base), C being a run-time value.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#include "raster_common.glsl"
#include "tile_vote.glsl"

#define BATCH TILE_PIXELS
// Carried state per pixel: T, r, g, b, depth sum, contributors, last, done, then sems.
#define CARRY_STRIDE (BLEND_CARRY_BASE + CHUNK_CHANNELS)

layout(local_size_x = TILE_PIXELS) in;

#include "blend_params.glsl"

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
#include "tile_window.glsl"
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 5) buffer CarryBuf { float data[]; } carry;
layout(set = 0, binding = 6) writeonly buffer RgbBuf { float data[]; } out_rgb;
layout(set = 0, binding = 7) writeonly buffer AlphaBuf { float data[]; } out_alpha;
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

void main() {
    uint width = pc.width, height = pc.height, channels = pc.channels;
    uint window_start = pc.window_start, window_len = pc.window_len, chunk_base = pc.chunk_base;
    bool write_rgb = pc.write_rgb != 0;
    TileWindow tw = tile_window_in_band(width, height, pc.tiles_x, window_start, window_len, pc.tile_row_base);
    uint t = tw.t, px = tw.px, py = tw.py, pix = tw.pix;
    bool inside = tw.inside;
    vec2 pixel = vec2(px, py);
    // Later windows only continue tiles that are longer; window 0 always writes (background).
    if (window_start > 0 && window_start >= tw.len) {
        return;
    }
    uint start = tw.start, end = tw.end;
    bool last_window = tw.last;

    float T = 1.0;
    vec3 rgb = vec3(0.0);
    float depth_sum = 0.0;
    uint n_contrib = 0;
    uint last = 0;
    bool done = !inside;
    float sem[CHUNK_CHANNELS > 0 ? CHUNK_CHANNELS : 1];
    [[unroll]] for (uint k = 0; k < max(CHUNK_CHANNELS, 1); k++) {
        sem[k] = 0.0;
    }
    if (window_start > 0 && inside) {
        uint c0 = pix * CARRY_STRIDE;
        T = carry.data[c0];
        rgb = vec3(carry.data[c0 + 1], carry.data[c0 + 2], carry.data[c0 + 3]);
        depth_sum = carry.data[c0 + 4];
        n_contrib = floatBitsToUint(carry.data[c0 + 5]);
        last = floatBitsToUint(carry.data[c0 + 6]);
        done = carry.data[c0 + 7] != 0.0;
        [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
            sem[k] = carry.data[c0 + BLEND_CARRY_BASE + k];
        }
    }

    for (uint b = start; b < end; b += BATCH) {
        // Stop the tile once every pixel is done.
        if (workgroup_all_done(done)) {
            break;
        }
        uint idx = b + t;
        if (idx < end) {
            uint g = isect_ids.data[idx];
            s_xy_depth_opacity[t] = xy_depth_opacity.data[g];
            s_frac[t] = xy_frac.data[g];
            s_conic[t] = conics.data[g];
#if !defined(MEDIAN_DEPTH)
            s_color[t] = colors.data[g];
#endif
#if defined(LABEL_ARGMAX)
            uint cls = classes.data[g];
            [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
                s_sem[t * CHUNK_CHANNELS + k] = cls == chunk_base + k ? 1.0 : 0.0;
            }
#elif CHUNK_CHANNELS > 0
            [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
                uint c = chunk_base + k;
                s_sem[t * CHUNK_CHANNELS + k] = c < channels ? sem_in.data[g * channels + c] : 0.0;
            }
#endif
        }
        barrier();
        uint count = min(BATCH, end - b);
        for (uint j = 0; j < count && !done; j++) {
            vec4 g = s_xy_depth_opacity[j];
            vec3 con = s_conic[j].xyz;
            vec2 d = pixel_offset(g.xy, s_frac[j], pixel);
            float sigma = conic_sigma(con, d);
            if (sigma < 0.0) {
                continue;
            }
            float alpha = min(ALPHA_MAX, g.w * exp(-sigma));
            if (alpha < ALPHA_MIN) {
                continue;
            }
            float next_t = T * (1.0 - alpha);
#if defined(MEDIAN_DEPTH)
            // The Gaussian that takes the pixel's transmittance below one half: its depth is
            // the pixel's (held in depth_sum, the carried state's depth slot); nothing
            // behind it is needed.
            if (next_t < MEDIAN_T) {
                depth_sum = g.z;
                T = next_t;
                done = true;
                break;
            }
#endif
            if (next_t <= T_MIN) {
                done = true;
                break;
            }
            float weight = alpha * T;
            if (write_rgb) {
                rgb += weight * s_color[j].rgb;
                depth_sum += weight * g.z;
            }
#if CHUNK_CHANNELS > 0
            [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
                sem[k] += weight * s_sem[j * CHUNK_CHANNELS + k];
            }
#endif
            T = next_t;
            n_contrib++;
            last = b + j;
        }
        barrier(); // the next batch overwrites the shared arrays
    }

    if (!inside) {
        return;
    }
    if (!last_window) {
        uint c0 = pix * CARRY_STRIDE;
        carry.data[c0] = T;
        carry.data[c0 + 1] = rgb.r;
        carry.data[c0 + 2] = rgb.g;
        carry.data[c0 + 3] = rgb.b;
        carry.data[c0 + 4] = depth_sum;
        carry.data[c0 + 5] = uintBitsToFloat(n_contrib);
        carry.data[c0 + 6] = uintBitsToFloat(last);
        carry.data[c0 + 7] = done ? 1.0 : 0.0;
        [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
            carry.data[c0 + BLEND_CARRY_BASE + k] = sem[k];
        }
        return;
    }
#if defined(MEDIAN_DEPTH)
    // 0 where the transmittance never fell below one half (no surface to test against).
    out_depth.data[pix] = T < MEDIAN_T ? depth_sum : 0.0;
    return;
#endif
    float acc_alpha = 1.0 - T;
    if (write_rgb) {
        vec3 c = rgb + T * pc.background;
        out_rgb.data[3 * pix] = c.r;
        out_rgb.data[3 * pix + 1] = c.g;
        out_rgb.data[3 * pix + 2] = c.b;
        out_alpha.data[pix] = acc_alpha;
        out_depth.data[pix] = acc_alpha > 0.0 ? depth_sum / acc_alpha : 0.0;
        out_final_t.data[pix] = T;
        out_last.data[pix] = last;
        out_n_contrib.data[pix] = n_contrib;
    }
#if defined(LABEL_ARGMAX)
    // The largest normalized value so far, later classes winning ties (as a host argmax
    // over the whole vector taking the last maximum would).
    uvec2 best = chunk_base == 0 ? uvec2(floatBitsToUint(0.0), NO_LABEL) : label_best.data[pix];
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        uint c = chunk_base + k;
        float v = acc_alpha > 0.0 ? sem[k] / acc_alpha : 0.0;
        if (c < channels && (best.y == NO_LABEL || v >= uintBitsToFloat(best.x))) {
            best = uvec2(floatBitsToUint(v), c);
        }
    }
    label_best.data[pix] = best;
#elif CHUNK_CHANNELS > 0
    [[unroll]] for (uint k = 0; k < CHUNK_CHANNELS; k++) {
        uint c = chunk_base + k;
        if (c < channels) {
            out_sem.data[pix * channels + c] = sem[k];
            out_sem_norm.data[pix * channels + c] = acc_alpha > 0.0 ? sem[k] / acc_alpha : 0.0;
        }
    }
#endif
}
