// The sort passes' CPU-driver forms (count_wide.comp, scatter_wide.comp), which the host
// picks where it picks every `*_wide` kernel (src/gpu/caps.rs, `cpu_forms`). A CPU
// driver (lavapipe) runs a workgroup as SIMD vectors and reads shared memory one lane at a
// time; the GPU form's ranking (a ballot per digit bit, shared-memory histograms and
// sorting, five barriers a round) cost it 120 ns a key and a pass (4M keys), the runs
// below 24 ns. Here a workgroup of SORT_WIDE_LANES
// invocations takes the same block of SORT_BLOCK keys (the same block count, histogram and
// scan as the GPU forms), each invocation a run of SORT_RUN consecutive keys, which it
// walks one after another with a private histogram: keys in order, no ballot, two barriers
// a block. Digits are RADIX_BITS_WIDE wide (the host plans the passes by form): fewer
// passes over the keys than the GPU forms', for a histogram of RADIX_WIDE counters per run
// (its loops not unrolled: unrolled, 16 counters took twice the time of 64 rolled). The
// results are the GPU forms' to the bit (a stable sort has one result).
#ifndef SORT_WIDE_RUNS_GLSL
#define SORT_WIDE_RUNS_GLSL

#include "sort_layout.glsl"

#define SORT_RUN (SORT_BLOCK / SORT_WIDE_LANES)

layout(local_size_x = SORT_WIDE_LANES) in;

// Per (digit, lane): the keys of that digit in the lane's run (then, in scatter_wide, the
// run's first output slot for the digit).
shared uint run_digits[RADIX_WIDE * SORT_WIDE_LANES];

// The keys [begin, end) of the invocation's run: up to SORT_RUN from its start, none past n.
uvec2 run_range(uint n) {
    uint begin = gl_WorkGroupID.x * SORT_BLOCK + gl_LocalInvocationIndex * SORT_RUN;
    return uvec2(begin, max(begin, min(begin + SORT_RUN, n)));
}

uint key_digit(uint key) {
    return bitfieldExtract(key, int(pc.shift), int(pc.bits));
}

// Counts the digits of the keys in `run` into `hist` and run_digits.
void count_run(uvec2 run, out uint hist[RADIX_WIDE]) {
    for (uint d = 0; d < RADIX_WIDE; d++) {
        hist[d] = 0;
    }
    for (uint i = run.x; i < run.y; i++) {
        hist[key_digit(keys_in.data[i])]++;
    }
    uint lane = gl_LocalInvocationIndex;
    for (uint d = 0; d < RADIX_WIDE; d++) {
        run_digits[d * SORT_WIDE_LANES + lane] = hist[d];
    }
}

#endif
