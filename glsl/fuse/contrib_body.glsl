// FlashSplat contribution accumulation (docs/papers.md): for every pixel with label e, walk the
// tile's depth-sorted list exactly as forward blending does and add each Gaussian's
// weight alpha * T into A[e, gaussian]. Included by contrib_fixed.comp (64-bit fixed-point
// integers: order-independent, so A is identical run to run) and contrib_float.comp (float
// atomics).
//
// Every lane walks every entry until all lanes of its subgroup are done (a done or
// unlabeled pixel contributes 0), so each step is uniform across the subgroup: lanes that
// share the label (neighbouring pixels mostly do) are summed in the subgroup first and one
// lane does the atomic. mode 1 keeps only the pixel that holds the Gaussian's projected
// center: the weighted vote. per_view divides each weight by the Gaussian's projected
// footprint in this view, 2 pi opacity sqrt(det Sigma2d), so a view adds the share of the
// Gaussian it sees under each label (at most about 1) instead of a number of pixels: near
// views no longer outweigh far ones.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "raster_common.glsl"
#include "tile_vote.glsl"

#define BATCH TILE_PIXELS
// The row a step adds to when it adds nothing: an unlabeled pixel, or a weight of 0.
#define NO_ROW NO_LABEL

layout(local_size_x = TILE_PIXELS) in;

layout(push_constant) uniform ContribParams {
    // Addresses of the per-Gaussian arrays (addressed_arrays.glsl).
    uvec2 xy_depth_opacity_addr;
    uvec2 xy_frac_addr;
    uvec2 conics_addr;
    uvec2 contrib_addr; // the pass's evidence rows, [rows][n] (the includer's entry type)
    uint width;
    uint height;
    uint tiles_x;
    uint n;
    uint window_start; // first entry of each tile's list this dispatch walks
    uint window_len;   // entries it walks at most
    uint row_begin;    // first class row of the evidence this pass holds
    uint rows;         // class rows this pass holds
    uint center_only;  // 1: only the pixel holding the center counts (weighted vote); 0: every pixel (A)
    uint per_view;     // 1: each view's weights divided by the Gaussian's projected footprint
    uint tile_row_base; // first tile row of this dispatch's band
} pc;

#include "addressed_arrays.glsl"
#define xy_depth_opacity Vec4Array(pc.xy_depth_opacity_addr)
#define xy_frac Vec2Array(pc.xy_frac_addr)
#define conics Vec4Array(pc.conics_addr)

layout(set = 0, binding = 0) readonly buffer RangesBuf { uvec2 data[]; } tile_ranges;
#include "tile_window.glsl"
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 4) readonly buffer LabelsBuf { uint data[]; } labels; // compact class per pixel
layout(set = 0, binding = 5) buffer CarryBuf { vec2 data[]; } carry;           // (T, done) between windows
// The binning's status words: a binning whose lists overflowed (or wrapped) is recorded
// again with larger lists, so its accumulation must add nothing (A is a running sum).
layout(set = 0, binding = 8) readonly buffer StatusBuf { uint data[]; } status;

shared vec4 s_xy_depth_opacity[BATCH]; // floor(mean2d) depth opacity
shared vec2 s_frac[BATCH];
shared vec4 s_conic[BATCH];
shared uint s_id[BATCH];
shared float s_scale[BATCH]; // per_view: 1 / footprint; else 1

void accumulate(uint row, uint gaussian, float w);

void main() {
    uint width = pc.width, height = pc.height, n = pc.n;
    uint window_start = pc.window_start, window_len = pc.window_len, row_begin = pc.row_begin, rows = pc.rows;
    if (status.data[ST_OVERFLOW] != 0 || status.data[ST_ISECT_WRAPPED] != 0) {
        return;
    }
    TileWindow tw = tile_window_in_band(width, height, pc.tiles_x, window_start, window_len, pc.tile_row_base);
    uint t = tw.t, px = tw.px, py = tw.py, pix = tw.pix;
    bool inside = tw.inside;
    vec2 pixel = vec2(px, py);
    if (window_start >= tw.len) {
        return;
    }
    uint start = tw.start, end = tw.end;
    bool last_window = tw.last;

    // Rows of A this pass holds: labels outside [row_begin, row_begin + rows) wait for
    // their own pass (unsigned wrap makes labels below row_begin fail the test too).
    uint label = inside ? labels.data[pix] : NO_LABEL;
    uint row = label - row_begin;
    bool labeled = label != NO_LABEL && row < rows;
    float T = 1.0;
    bool done = !labeled;
    if (window_start > 0 && labeled) {
        vec2 c = carry.data[pix];
        T = c.x;
        done = c.y != 0.0;
    }

    for (uint b = start; b < end; b += BATCH) {
        // Stop the tile once every pixel is done.
        if (workgroup_all_done(done)) {
            break;
        }
        uint idx = b + t;
        if (idx < end) {
            uint g = isect_ids.data[idx];
            s_id[t] = g;
            s_xy_depth_opacity[t] = xy_depth_opacity.data[g];
            s_frac[t] = xy_frac.data[g];
            s_conic[t] = conics.data[g];
            // The footprint is the Gaussian's, not the pixel's: once per entry, not per step.
            // The conic is the inverse of Sigma2d: sqrt(det Sigma2d) = 1 / sqrt(det conic).
            vec4 con = s_conic[t];
            s_scale[t] = pc.per_view == 1
                ? sqrt(max(con.x * con.z - con.y * con.y, 0.0)) / (TWO_PI * s_xy_depth_opacity[t].w)
                : 1.0;
        }
        barrier();
        uint count = min(BATCH, end - b);
        for (uint j = 0; j < count; j++) {
            // A subgroup-uniform exit, as blending's per-lane one: once every pixel of the
            // subgroup is saturated or unlabeled, the rest of the batch adds nothing.
            if (subgroupAll(done)) {
                break;
            }
            float w = 0.0;
            vec4 g = s_xy_depth_opacity[j];
            if (!done) {
                vec3 con = s_conic[j].xyz;
                vec2 d = pixel_offset(g.xy, s_frac[j], pixel);
                float sigma = conic_sigma(con, d);
                float alpha = sigma < 0.0 ? 0.0 : min(ALPHA_MAX, g.w * exp(-sigma));
                if (alpha >= ALPHA_MIN) {
                    float next_t = T * (1.0 - alpha);
                    if (next_t <= T_MIN) {
                        done = true;
                    } else {
                        w = alpha * T;
                        T = next_t;
                    }
                }
            }
            if (pc.center_only == 1 && g.xy != pixel) {
                w = 0.0;
            }
            w *= s_scale[j];
            accumulate(w > 0.0 ? row : NO_ROW, s_id[j], w);
        }
        barrier();
    }
    if (labeled && !last_window) {
        carry.data[pix] = vec2(T, done ? 1.0 : 0.0);
    }
}
