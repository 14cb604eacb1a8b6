// One entry of a fusion pass's evidence rows, widened to 64 bits: vote counts are one word
// per entry, fixed-point contributions two (little-endian halves of a uint64). Shared by the
// assignment kernels (class_mass.comp, assign_fold.comp); the includer declares push
// constants `pc` with `n`, `words` and the address of the rows, `evidence_addr` (uint
// words, [rows][n] entries: a pass may pass one binding, addressed_arrays.glsl).
#ifndef EVIDENCE_ENTRY_GLSL
#define EVIDENCE_ENTRY_GLSL

#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#include "addressed_arrays.glsl"
#define evidence UintArray(pc.evidence_addr)

uint64_t evidence_entry(uint row, uint gaussian) {
    uint at = (row * pc.n + gaussian) * pc.words;
    uint hi = pc.words == 2 ? evidence.data[at + 1] : 0u;
    return packUint2x32(uvec2(evidence.data[at], hi));
}

#endif
