#version 460
// Lays out the new set: Gaussian i owns output slots [out_offsets[i], out_offsets[i + 1]),
// none if pruned, one if kept, two if densified (the original and its clone, or the two
// split children). Writes each slot's source Gaussian and kind, and the offset a split
// child adds to its mean: R(q) * (exp(log_scales) * z), z ~ N(0, I) from the hash of
// (index, child, seed). Counts clones and splits; invocation n publishes the new count.
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "densify_common.glsl"
#include "projection.glsl" // quat_to_mat

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform DensifyLayoutParams {
    uint n;
    float ln_split_scale; // densified Gaussians with a larger max log-scale split
    uvec2 seed;
    // By address (addressed_arrays.glsl): log-scales [n][3], quaternions [n], output
    // offsets [n + 1], and per slot its source, kind and mean offset [slots][3] written.
    uvec2 log_scales_addr;
    uvec2 quats_addr;
    uvec2 out_offsets_addr;
    uvec2 slot_source_addr;
    uvec2 slot_kind_addr;
    uvec2 slot_mean_delta_addr;
} pc;

#include "addressed_arrays.glsl"
#define log_scales FloatArray(pc.log_scales_addr)
#define quats Vec4Array(pc.quats_addr)
#define slot_mean_delta FloatArrayRW(pc.slot_mean_delta_addr)
#define out_offsets UintArray(pc.out_offsets_addr)
#define slot_source UintArrayRW(pc.slot_source_addr)
#define slot_kind UintArrayRW(pc.slot_kind_addr)
layout(set = 0, binding = 6) buffer StatusBuf { uint data[]; } status;

void write_slot(uint j, uint source, uint kind, vec3 delta) {
    slot_source.data[j] = source;
    slot_kind.data[j] = kind;
    slot_mean_delta.data[3 * j] = delta.x;
    slot_mean_delta.data[3 * j + 1] = delta.y;
    slot_mean_delta.data[3 * j + 2] = delta.z;
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    bool cloned = false;
    bool split = false;
    if (i < pc.n) {
        uint o = out_offsets.data[i];
        uint count = out_offsets.data[i + 1] - o;
        if (count == 1) {
            write_slot(o, i, SLOT_KEEP, vec3(0.0));
        } else if (count == 2) {
            vec3 ls = vec3(log_scales.data[3 * i], log_scales.data[3 * i + 1],
                           log_scales.data[3 * i + 2]);
            split = max3(ls) > pc.ln_split_scale;
            cloned = !split;
            if (cloned) {
                write_slot(o, i, SLOT_KEEP, vec3(0.0));
                write_slot(o + 1, i, SLOT_CLONE, vec3(0.0));
            } else {
                mat3 r = quat_to_mat(normalize(quats.data[i]));
                vec3 s = exp(ls);
                write_slot(o, i, SLOT_SPLIT0, r * (s * split_normal(i, 0, pc.seed)));
                write_slot(o + 1, i, SLOT_SPLIT1, r * (s * split_normal(i, 1, pc.seed)));
            }
        }
    } else if (i == pc.n) {
        status.data[DS_NEW_N] = out_offsets.data[pc.n];
    }
    // One atomic per subgroup (every invocation reaches this: no early return above).
    uint clones = subgroupAdd(cloned ? 1u : 0u);
    uint splits = subgroupAdd(split ? 1u : 0u);
    if (subgroupElect()) {
        if (clones > 0) {
            atomicAdd(status.data[DS_CLONED], clones);
        }
        if (splits > 0) {
            atomicAdd(status.data[DS_SPLIT], splits);
        }
    }
}
