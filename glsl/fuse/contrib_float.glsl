// Contributions as float32 atomics (faster on some devices; sums depend on atomic order).
#extension GL_EXT_shader_atomic_float : require
#define Amount float
#include "contrib_body.glsl"

#define contrib FloatArrayRW(pc.contrib_addr) // [rows][n]

float amount_of(float w) {
    return w;
}

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

void add_own(uint row, uint gaussian, float amount) {
    atomicAdd(contrib.data[row * pc.n + gaussian], amount);
}
