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
// views no longer outweigh far ones. An invocation takes PIXELS of the tile's pixels
// (tile_window.glsl: one on a GPU, more in the `*_wide` kernels for CPU drivers) and adds
// their weights for one row together before the subgroup does. fuse/region_footprint.glsl
// sets MEDIAN_DEPTH_OUT (the walk also writes each pixel's median and opaque depths, as
// raster/blend_median_depth.comp finds them from the same steps; an unlabeled pixel beside
// a labeled one is walked for them alone, adding nothing) and
// ENTRY_TARGETS (the sums go per list entry instead of per Gaussian).
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "raster_common.glsl"
#include "tile_vote.glsl"

#define BATCH TILE_PIXELS
// The row a step adds to when it adds nothing: an unlabeled pixel, or a weight of 0.
#define NO_ROW NO_LABEL

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
layout(local_size_x = LANES) in;
layout(set = 0, binding = 1) readonly buffer IdsBuf { uint data[]; } isect_ids;
layout(set = 0, binding = 4) readonly buffer LabelsBuf { uint data[]; } labels; // compact class per pixel
layout(set = 0, binding = 5) buffer CarryBuf { vec2 data[]; } carry;           // (T, done) between windows
// The binning's status words: a binning whose lists overflowed (or wrapped) is recorded
// again with larger lists, so its accumulation must add nothing (A is a running sum).
layout(set = 0, binding = 8) readonly buffer StatusBuf { uint data[]; } status;
#if defined(MEDIAN_DEPTH_OUT)
// Per pixel, the depth of the Gaussian that takes its transmittance below MEDIAN_T (the
// median depth), and below OPAQUE_T (the opaque depth); each left as it was (the caller
// zeroes them) where it never falls that far, or the pixel is unlabeled with no labeled
// pixel around it. The unlabeled ones beside a labeled pixel too: the consensus's
// visibility test reads a center's 3x3 pixels, labeled or not, as the median depth pass
// writes them for a GPU.
layout(set = 0, binding = 9) writeonly buffer DepthBuf { float data[]; } out_depth;
layout(set = 0, binding = 10) writeonly buffer OpaqueDepthBuf { float data[]; } out_opaque_depth;
#endif

shared vec4 s_xy_depth_opacity[BATCH]; // floor(mean2d) depth opacity
shared vec2 s_frac[BATCH];
shared vec4 s_conic[BATCH];
shared uint s_id[BATCH];
shared float s_scale[BATCH]; // per_view: 1 / footprint; else 1

#if defined(ENTRY_TARGETS)
// The includer adds per entry of the tile's list (the tile's own: no other workgroup walks
// it), not per Gaussian.
#define STEP_TARGET (b + j)
#else
#define STEP_TARGET s_id[j]
#endif

// The includer's evidence entry: `Amount` (a weight as the entries sum it), `amount_of(w)`,
// `accumulate(row, gaussian, amount)` (from uniform control flow; NO_ROW adds nothing) and
// `add_own(row, gaussian, amount)` (one invocation's amount, not summed in the subgroup).
Amount amount_of(float w);
void accumulate(uint row, uint gaussian, Amount amount);
void add_own(uint row, uint gaussian, Amount amount);

// One pixel's walk: its row of the evidence, transmittance, and whether it is done.
struct Pixel {
    uint row;
    bool labeled;
    float T;
    bool done;
#if defined(MEDIAN_DEPTH_OUT)
    // Unlabeled: walked for its depths alone (to saturation, as a labeled pixel: stopping
    // at the opaque depth would take a branch in the step).
    bool depth_only;
    // The depth of the Gaussian that took T below MEDIAN_T in this window (0: none did),
    // written once at the window's end: a store in the walk's steps, even one no pixel
    // takes, cost lavapipe's footprint walk 7.7 s against 5.3 s (60 views of 320x240).
    float median;
    float opaque; // the same for OPAQUE_T: the opaque depth
#endif
};

#if defined(MEDIAN_DEPTH_OUT)
// Whether one of the 8 pixels around `tw`'s is labeled, or lies outside the band of rows
// this dispatch binds (and may be): the visibility test reads the opaque depths of the 3x3
// pixels around a labeled center pixel, and no other unlabeled pixel's. Walking only these
// of the unlabeled ones keeps a map's holes (30% of its pixels, in blobs) from costing the
// walk as much again.
bool beside_labeled(TileWindow tw) {
    int first = int(pc.tile_row_base * TILE_SIZE);
    int end = min(int(pc.height), first + int(gl_NumWorkGroups.y * TILE_SIZE));
    bool beside = false;
    [[unroll]] for (int dy = -1; dy <= 1; dy++) {
        [[unroll]] for (int dx = -1; dx <= 1; dx++) {
            int x = int(tw.px) + dx, y = int(tw.py) + dy;
            if (x < 0 || x >= int(pc.width) || y < 0 || y >= int(pc.height)) {
                continue;
            }
            if (y < first || y >= end) {
                beside = true;
            } else if (labels.data[uint(y - first) * pc.width + uint(x)] != NO_LABEL) {
                beside = true;
            }
        }
    }
    return beside;
}
#endif

// Whether the walk steps through pixel `p`'s Gaussians.
bool walked(Pixel p) {
#if defined(MEDIAN_DEPTH_OUT)
    return p.labeled || p.depth_only;
#else
    return p.labeled;
#endif
}

Pixel pixel_start(TileWindow tw, uint window_start) {
    // Rows of A this pass holds: labels outside [row_begin, row_begin + rows) wait for
    // their own pass (unsigned wrap makes labels below row_begin fail the test too).
    uint label = tw.inside ? labels.data[tw.pix] : NO_LABEL;
    Pixel p;
    p.row = label - pc.row_begin;
    p.labeled = label != NO_LABEL && p.row < pc.rows;
    p.T = 1.0;
    p.done = !p.labeled;
#if defined(MEDIAN_DEPTH_OUT)
    p.depth_only = tw.inside && label == NO_LABEL && beside_labeled(tw);
    p.row = p.depth_only ? NO_ROW : p.row;
    p.done = p.done && !p.depth_only;
    p.median = 0.0;
    p.opaque = 0.0;
#endif
    if (window_start > 0 && walked(p)) {
        vec2 c = carry.data[tw.pix];
        p.T = c.x;
        p.done = c.y != 0.0;
    }
    return p;
}

#if PIXELS > 1
// The step's conic and fraction, read once for all the invocation's pixels (each read of
// shared memory is a loop over the lanes on a CPU driver).
vec3 step_conic;
vec2 step_frac;
#define STEP_CONIC step_conic
#define STEP_FRAC step_frac
#else
// Read only where the pixel is not done.
#define STEP_CONIC s_conic[j].xyz
#define STEP_FRAC s_frac[j]
#endif

// The weight alpha * T pixel `p` (`tw`) gives batch slot `j` (0 where it takes none).
float contrib_step(inout Pixel p, TileWindow tw, uint j, vec4 g) {
    float w = 0.0;
    if (!p.done) {
        vec2 d = pixel_offset(g.xy, STEP_FRAC, vec2(tw.px, tw.py));
        float sigma = conic_sigma(STEP_CONIC, d);
        // As blend_step: an exponent that is negative or NaN draws nothing (min(0.999, NaN)
        // is 0.999 on some drivers: a near-opaque splat).
        float alpha = sigma >= 0.0 ? min(ALPHA_MAX, g.w * exp(-sigma)) : 0.0;
        if (alpha >= ALPHA_MIN) {
            float next_t = p.T * (1.0 - alpha);
#if defined(MEDIAN_DEPTH_OUT)
            p.median = p.T >= MEDIAN_T && next_t < MEDIAN_T ? g.z : p.median;
            p.opaque = p.T >= OPAQUE_T && next_t < OPAQUE_T ? g.z : p.opaque;
#endif
            if (next_t <= T_MIN) {
                p.done = true;
            } else {
                w = alpha * p.T;
                p.T = next_t;
            }
        }
    }
    if (pc.center_only == 1 && g.xy != vec2(tw.px, tw.py)) {
        w = 0.0;
    }
#if defined(MEDIAN_DEPTH_OUT)
    // A pixel walked for its depths adds nothing (a weight of 0 also keeps the sums of
    // several pixels an invocation to the labeled ones'). A factor, not a branch: a branch
    // here cost lavapipe's footprint walk 8.6 s against 5.2 s (60 views of 320x240).
    w *= p.depth_only ? 0.0 : 1.0;
#endif
    return w * s_scale[j];
}

bool all_done(Pixel px[PIXELS]) {
    bool done = true;
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        done = done && px[q].done;
    }
    return done;
}

#if PIXELS > 1
bool pending(Amount amount[PIXELS]) {
    bool any = false;
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        any = any || amount[q] != amount_of(0.0);
    }
    return any;
}

// The row of the first pixel with an amount left (NO_ROW: none), and the sum of the
// amounts of its pixels of that row, which are then cleared.
Amount take_row(inout Amount amount[PIXELS], Pixel px[PIXELS], out uint row) {
    row = NO_ROW;
    Amount sum = amount_of(0.0);
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        if (amount[q] != amount_of(0.0) && (row == NO_ROW || px[q].row == row)) {
            row = px[q].row;
            sum += amount[q];
            amount[q] = amount_of(0.0);
        }
    }
    return sum;
}
#endif

// Loads entry `idx` of the tile's list into batch slot `slot`.
void load_entry(uint idx, uint slot) {
    uint g = isect_ids.data[idx];
    s_id[slot] = g;
    vec4 xy_depth_opacity_g = xy_depth_opacity.data[g];
    vec4 con = conics.data[g];
    s_xy_depth_opacity[slot] = xy_depth_opacity_g;
    s_frac[slot] = xy_frac.data[g];
    s_conic[slot] = con;
    // The footprint is the Gaussian's, not the pixel's: once per entry, not per step.
    // The conic is the inverse of Sigma2d: sqrt(det Sigma2d) = 1 / sqrt(det conic).
    s_scale[slot] = pc.per_view == 1
        ? sqrt(max(con.x * con.z - con.y * con.y, 0.0)) / (TWO_PI * xy_depth_opacity_g.w)
        : 1.0;
}

void main() {
    uint width = pc.width, height = pc.height;
    uint window_start = pc.window_start, window_len = pc.window_len;
    if (status.data[ST_OVERFLOW] != 0 || status.data[ST_ISECT_WRAPPED] != 0) {
        return;
    }
    TileWindow tw[PIXELS];
    tile_windows(tw, width, height, pc.tiles_x, window_start, window_len, pc.tile_row_base);
    if (window_start >= tw[0].len) {
        return;
    }
    uint start = tw[0].start, end = tw[0].end;
    Pixel px[PIXELS];
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        px[q] = pixel_start(tw[q], window_start);
    }

    for (uint b = start; b < end; b += BATCH) {
        // Stop the tile once every pixel is done.
        if (workgroup_all_done(all_done(px))) {
            break;
        }
        [[unroll]] for (uint q = 0; q < PIXELS; q++) {
            uint slot = invocation_slot(q);
            if (b + slot < end) {
                load_entry(b + slot, slot);
            }
        }
        barrier();
        uint count = min(BATCH, end - b);
        for (uint j = 0; j < count; j++) {
            // A subgroup-uniform exit, as blending's per-lane one: once every pixel of the
            // subgroup is saturated or unlabeled, the rest of the batch adds nothing.
            if (subgroupAll(all_done(px))) {
                break;
            }
            vec4 g = s_xy_depth_opacity[j];
            uint id = STEP_TARGET;
#if PIXELS == 1
            float w = contrib_step(px[0], tw[0], j, g);
            accumulate(w > 0.0 ? px[0].row : NO_ROW, id, amount_of(w));
#else
            step_conic = s_conic[j].xyz;
            step_frac = s_frac[j];
            Amount amount[PIXELS];
            [[unroll]] for (uint q = 0; q < PIXELS; q++) {
                float w = contrib_step(px[q], tw[q], j, g);
                amount[q] = amount_of(w);
            }
            // The invocation's pixels by row: the first row's sum is summed in the subgroup
            // by accumulate (mostly the only one: neighbouring pixels share their label),
            // any other pixel's weight is added on its own. No loop and no call skipped:
            // lavapipe's loop cap counts every iteration (the windows of 32,768 entries
            // leave room for one a step), and it seems to pay for calls under a branch no
            // lane takes (inferred from times, not from its source: a second accumulate
            // call and one a pixel after it, each under such a branch, took FlashSplat
            // 6.5 s where this takes 3.4 s), so the rest costs one plain atomic a pixel.
            if (subgroupAny(pending(amount))) {
                uint row;
                Amount sum = take_row(amount, px, row);
                accumulate(row, id, sum);
                [[unroll]] for (uint q = 0; q < PIXELS; q++) {
                    if (amount[q] != amount_of(0.0)) {
                        add_own(px[q].row, id, amount[q]);
                    }
                }
            }
#endif
        }
        barrier();
    }
    [[unroll]] for (uint q = 0; q < PIXELS; q++) {
        if (walked(px[q]) && !tw[q].last) {
            carry.data[tw[q].pix] = vec2(px[q].T, px[q].done ? 1.0 : 0.0);
        }
#if defined(MEDIAN_DEPTH_OUT)
        // A depth is in front of the camera: never 0.
        if (px[q].median != 0.0) {
            out_depth.data[tw[q].pix] = px[q].median;
        }
        if (px[q].opaque != 0.0) {
            out_opaque_depth.data[tw[q].pix] = px[q].opaque;
        }
#endif
    }
}
