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

layout(local_size_x = TILE_PIXELS) in;

#include "blend_params.glsl"

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
#include "tile_window.glsl"
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 7) readonly buffer FinalTBuf { float data[]; } final_t;
layout(set = 0, binding = 8) readonly buffer LastBuf { uint data[]; } last_entry;
layout(set = 0, binding = 9) readonly buffer CountBuf { uint data[]; } n_contrib;
layout(set = 0, binding = 10) readonly buffer SemNormBuf { float data[]; } sem_norm;
layout(set = 0, binding = 11) readonly buffer VRgbBuf { float data[]; } v_rgb;
layout(set = 0, binding = 12) readonly buffer VAlphaBuf { float data[]; } v_alpha;
layout(set = 0, binding = 13) readonly buffer VSemNormBuf { float data[]; } v_sem_norm;
layout(set = 0, binding = 14) buffer CarryBuf { float data[]; } carry;

shared vec4 s_xy_depth_opacity[BATCH];
shared vec2 s_frac[BATCH];
shared vec4 s_conic[BATCH];
shared vec4 s_color[BATCH];
shared uint s_id[BATCH];
shared float s_sem[BATCH * SEM_CHUNK];
shared uint s_bound; // one past the furthest entry any pixel of the tile blended

void main() {
    uint width = pc.width, height = pc.height, channels = pc.channels;
    uint window_start = pc.window_start, window_len = pc.window_len, chunk_base = pc.chunk_base;
#ifdef SEM_ONLY
    bool with_rgb = false; // only the semantic vectors' gradient (geometry frozen)
#else
    bool with_rgb = chunk_base == 0;
#endif
    TileWindow tw = tile_window_in_band(width, height, pc.tiles_x, window_start, window_len,
                                        pc.tile_row_base);
    if (window_start > 0 && window_start >= tw.len) {
        return; // this tile's list ends before the window
    }
    uint t = tw.t, pix = tw.pix;
    bool inside = tw.inside;
    vec2 pixel = vec2(tw.px, tw.py);

    // What this pixel blended: list entries [tile start, bound).
    uint bound = 0;
    float t_final = 1.0;
    vec3 v_col = vec3(0.0);
    float v_tfinal = 0.0; // dL/dT_final from the outputs that read it directly
    float v_sem[SEM_CHUNK];
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        v_sem[k] = 0.0;
    }
    if (inside && n_contrib.data[pix] > 0) {
        bound = last_entry.data[pix] + 1;
        t_final = final_t.data[pix];
        float covered = 1.0 - t_final;
#ifndef SEM_ONLY
        if (with_rgb) {
            v_col = vec3(v_rgb.data[3 * pix], v_rgb.data[3 * pix + 1], v_rgb.data[3 * pix + 2]);
            // rgb = sum + T_final * background; accumulated alpha = 1 - T_final.
            v_tfinal = dot(v_col, pc.background) - v_alpha.data[pix];
        }
#endif
        // Gaussian Semantics Eq. 2: sem_norm = sem / (1 - T_final), so dL/dsem = v / (1 - T_final) and
        // dL/dT_final += sum_k v_k sem_norm_k / (1 - T_final).
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            uint c = chunk_base + k;
            if (c < channels && covered > 0.0) {
                float v = v_sem_norm.data[pix * channels + c];
                v_sem[k] = v / covered;
#ifndef SEM_ONLY
                v_tfinal += v * sem_norm.data[pix * channels + c] / covered;
#endif
            }
        }
    }

    // Per-pixel state, from the last window of the list or carried from the one after.
    float T = t_final;
    vec3 s_rgb = vec3(0.0);
    float s_sem_acc[SEM_CHUNK];
    [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
        s_sem_acc[k] = 0.0;
    }
    uint c0 = pix * CARRY_STRIDE;
    if (!tw.last && inside) {
        T = carry.data[c0];
        s_rgb = vec3(carry.data[c0 + 1], carry.data[c0 + 2], carry.data[c0 + 3]);
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            s_sem_acc[k] = carry.data[c0 + 4 + k];
        }
    }

    if (t == 0) {
        s_bound = 0;
    }
    barrier();
    uint sg_bound = subgroupMax(bound);
    if (subgroupElect()) {
        atomicMax(s_bound, sg_bound);
    }
    barrier();
    uint start = tw.start;
    uint hi = min(tw.end, s_bound);

    // Batches back to front: [b0, b1) with b1 descending.
    for (uint b1 = hi; b1 > start; b1 -= min(BATCH, b1 - start)) {
        uint count = min(BATCH, b1 - start);
        uint b0 = b1 - count;
        if (t < count) {
            uint g = isect_ids.data[b0 + t];
            s_id[t] = g;
            s_xy_depth_opacity[t] = xy_depth_opacity.data[g];
            s_frac[t] = xy_frac.data[g];
            s_conic[t] = conics.data[g];
#ifndef SEM_ONLY
            s_color[t] = colors.data[g];
            [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
                uint c = chunk_base + k;
                s_sem[t * SEM_CHUNK + k] = c < channels ? sem_in.data[g * channels + c] : 0.0;
            }
#endif
        }
        barrier();
        for (uint jj = count; jj > 0; jj--) {
            uint j = jj - 1;
            bool live = b0 + j < bound;
            float alpha = 0.0;
            float gauss = 0.0;
            vec2 d = vec2(0.0);
            vec4 g = s_xy_depth_opacity[j];
            vec3 con = s_conic[j].xyz;
            if (live) {
                d = pixel_offset(g.xy, s_frac[j], pixel);
                float sigma = conic_sigma(con, d);
                gauss = exp(-sigma);
                alpha = min(ALPHA_MAX, g.w * gauss);
                live = sigma >= 0.0 && alpha >= ALPHA_MIN;
            }
            if (!subgroupAny(live)) {
                continue;
            }
            float vals[STEP_VALUES];
            [[unroll]] for (uint k = 0; k < STEP_VALUES; k++) {
                vals[k] = 0.0;
            }
            if (live) {
                float one_minus = 1.0 - alpha;
                float t_i = T / one_minus; // transmittance in front of this Gaussian
                float w = alpha * t_i;
#ifdef SEM_ONLY
                [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
                    vals[GRAD2D_STRIDE + k] = w * v_sem[k];
                }
#else
                // dL/dalpha: its own weight, the dimming of everything behind it, and T_final.
                float v_a = -v_tfinal * t_final / one_minus;
                if (with_rgb) {
                    vec3 c = s_color[j].rgb;
                    v_a += dot(v_col, c * t_i - s_rgb / one_minus);
                    s_rgb += w * c;
                    vals[6] = w * v_col.r;
                    vals[7] = w * v_col.g;
                    vals[8] = w * v_col.b;
                }
                [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
                    float s = s_sem[j * SEM_CHUNK + k];
                    v_a += v_sem[k] * (s * t_i - s_sem_acc[k] / one_minus);
                    s_sem_acc[k] += w * s;
                    vals[GRAD2D_STRIDE + k] = w * v_sem[k];
                }
                // alpha = min(0.999, o exp(-sigma)): no gradient through the clamp.
                if (g.w * gauss <= ALPHA_MAX) {
                    float v_sigma = -v_a * alpha;
                    vals[0] = v_sigma * (con.x * d.x + con.y * d.y);
                    vals[1] = v_sigma * (con.z * d.y + con.y * d.x);
                    vals[2] = v_sigma * 0.5 * d.x * d.x;
                    vals[3] = v_sigma * d.x * d.y;
                    vals[4] = v_sigma * 0.5 * d.y * d.y;
                    vals[5] = v_a * gauss;
                }
#endif
                T = t_i;
            }
            uint gid = s_id[j];
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
        barrier(); // the next batch overwrites the shared arrays
    }

    if (inside && window_start > 0) {
        carry.data[c0] = T;
        carry.data[c0 + 1] = s_rgb.r;
        carry.data[c0 + 2] = s_rgb.g;
        carry.data[c0 + 3] = s_rgb.b;
        [[unroll]] for (uint k = 0; k < SEM_CHUNK; k++) {
            carry.data[c0 + 4 + k] = s_sem_acc[k];
        }
    }
}
