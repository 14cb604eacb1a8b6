#version 460
// Contributions as float32 atomics (faster on some devices; sums depend on atomic order).
#extension GL_EXT_shader_atomic_float : require
#include "contrib_body.glsl"

#define contrib FloatArrayRW(pc.contrib_addr) // [rows][n]

void accumulate(uint row, uint gaussian, float w) {
    if (subgroupAllEqual(row)) {
        if (row != NO_ROW) {
            float s = subgroupAdd(w);
            if (subgroupElect()) {
                atomicAdd(contrib.data[row * pc.n + gaussian], s);
            }
        }
    } else if (row != NO_ROW) {
        atomicAdd(contrib.data[row * pc.n + gaussian], w);
    }
}
