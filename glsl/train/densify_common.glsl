// Shared by the densification kernels and src/train/densify.rs: the plan's status words,
// the kinds of output slots, the per-Gaussian tests, and the split RNG.
#ifndef DENSIFY_COMMON_GLSL
#define DENSIFY_COMMON_GLSL

// DENSIFY_WG_SIZE and the plan status words DS_* (u32 words, filled on the GPU and read
// once by the host).
#include "shared_constants.glsl"

// What an output slot holds, relative to its source Gaussian.
#define SLOT_KEEP 0u   // the Gaussian itself (also the original of a clone)
#define SLOT_CLONE 1u  // the copy a clone adds
#define SLOT_SPLIT0 2u // first child of a split
#define SLOT_SPLIT1 3u // second child of a split

// Mean over views of the 2D-gradient norm; 0 for a Gaussian no view saw.
float avg_grad(float accum, float count) {
    return count > 0.0 ? accum / count : 0.0;
}

float max3(vec3 v) {
    return max(v.x, max(v.y, v.z));
}

// Sort key that orders floats by decreasing value (ascending u32 order): flip a float's
// bits into an order-preserving u32, then complement.
uint descending_key(float f) {
    uint b = floatBitsToUint(f);
    uint ordered = (b & 0x80000000u) != 0 ? ~b : b | 0x80000000u;
    return ~ordered;
}

// pcg4d (Jarzynski and Olano, "Hash Functions for GPU Rendering", JCGT 2020): four
// well-mixed words from four input words. src/train/densify.rs reproduces it.
uvec4 pcg4d(uvec4 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    v ^= v >> 16u;
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    return v;
}

// Uniform in (0, 1), exact in f32: the top 24 bits plus half a step.
float unit_open(uint bits) {
    return (float(bits >> 8u) + 0.5) * (1.0 / 16777216.0);
}

// Standard normal draws of a split child (Box-Muller on the hash of (index, child, seed));
// the fourth draw is unused.
vec3 split_normal(uint index, uint child, uvec2 seed) {
    uvec4 h = pcg4d(uvec4(index, child, seed.x, seed.y));
    float r0 = sqrt(-2.0 * log(unit_open(h.x)));
    float r1 = sqrt(-2.0 * log(unit_open(h.z)));
    // Angles in [-pi, pi): where GPU sin and cos are most accurate.
    float a0 = 3.14159265358979 * (2.0 * unit_open(h.y) - 1.0);
    float a1 = 3.14159265358979 * (2.0 * unit_open(h.w) - 1.0);
    return vec3(r0 * cos(a0), r0 * sin(a0), r1 * cos(a1));
}

#endif
