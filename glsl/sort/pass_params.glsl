// Push constants of one radix pass (count.comp, scatter.comp): the digit, and the pass's
// input and output arrays by address (addressed_arrays.glsl), so sorting a scene's visible
// Gaussians is bounded by memory, not one binding (33.5M 4-byte keys on lavapipe).
#ifndef SORT_PASS_PARAMS_GLSL
#define SORT_PASS_PARAMS_GLSL

layout(push_constant) uniform SortPassParams {
    uvec2 keys_in_addr;
    uvec2 values_in_addr;   // scatter only
    uvec2 keys_out_addr;    // scatter only
    uvec2 values_out_addr;  // scatter only
    uint shift;
    uint bits; // digit width of this pass, 0..=RADIX_BITS (RADIX_BITS_WIDE: the wide forms)
} pc;

#include "addressed_arrays.glsl"
#define keys_in UintArray(pc.keys_in_addr)
#define values_in UintArray(pc.values_in_addr)
#define keys_out UintArrayRW(pc.keys_out_addr)
#define values_out UintArrayRW(pc.values_out_addr)

#endif
