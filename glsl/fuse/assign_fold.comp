#version 460
// Folds one pass's class rows into every Gaussian's running semantic assignment, so the
// host never holds the evidence matrix (src/fuse/assign_gpu.rs; the plain host version is
// assign_semantic_near in src/fuse/assign.rs). A class beats another by, in order: more
// evidence; more evidence summed over the Gaussian's k nearest neighbours; a higher rank of
// its evidence over the whole scene. Equal on all three is a tie, which leaves the Gaussian
// undecided unless a later class beats both. The comparison is a total preorder, so
// folding the rows pass by pass picks the winner of all classes at once. Each Gaussian's
// evidence is also summed over every class (the confidence's denominator). One invocation
// per Gaussian of the chunk [first, first + count) owns its state: no atomics.
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 256) in;

// The state of one Gaussian; the host's mirror is `FoldState` in src/fuse/assign_gpu.rs.
struct FoldState {
    uint64_t value; // the winner's evidence (0: nothing seen yet)
    uint64_t near;  // the winner's evidence summed over the neighbours
    uint64_t total; // evidence over every class folded so far
    uint class_;    // the winner's compact class
    uint tied;      // 1 when another class equals the winner on all three
};

layout(set = 0, binding = 1) readonly buffer KnnBuf { uint data[]; } knn;           // [count][k], from `first`
layout(set = 0, binding = 2) readonly buffer RankBuf { uint data[]; } scene_rank;   // [classes]
layout(set = 0, binding = 3) buffer StateBuf { FoldState data[]; } state;           // [count], from `first`

layout(push_constant) uniform FoldParams {
    uvec2 evidence_addr; // [rows][n] entries (evidence_entry.glsl)
    uint n;
    uint words;     // words per evidence entry: 1 (vote counts) or 2 (64-bit fixed point)
    uint first;     // the chunk's first Gaussian
    uint count;     // Gaussians in the chunk
    uint row_begin; // the pass's first compact class
    uint rows;      // classes in the pass
    uint k;         // neighbours per Gaussian (0: no neighbour tie-break)
} pc;

#include "evidence_entry.glsl"
#include "shared_constants.glsl" // NO_NEIGHBOUR

uint64_t neighbours_evidence(uint row, uint i) {
    uint64_t sum = 0;
    for (uint j = 0; j < pc.k; j++) {
        uint h = knn.data[i * pc.k + j];
        if (h != NO_NEIGHBOUR) {
            sum += evidence_entry(row, h);
        }
    }
    return sum;
}

// Sign of (value, near, rank) against the state's winner, compared in that order.
int compare_to_winner(uint64_t value, uint64_t near, uint rank, FoldState s) {
    if (value != s.value) {
        return value > s.value ? 1 : -1;
    }
    if (near != s.near) {
        return near > s.near ? 1 : -1;
    }
    uint winner_rank = scene_rank.data[s.class_];
    return rank == winner_rank ? 0 : (rank > winner_rank ? 1 : -1);
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) {
        return;
    }
    uint g = pc.first + i;
    FoldState s = state.data[i];
    for (uint row = 0; row < pc.rows; row++) {
        uint64_t value = evidence_entry(row, g);
        s.total += value;
        if (value == 0 || value < s.value) {
            continue; // unseen, or beaten on evidence alone
        }
        uint class_ = pc.row_begin + row;
        uint64_t near = neighbours_evidence(row, i);
        int order = s.value == 0 ? 1 : compare_to_winner(value, near, scene_rank.data[class_], s);
        if (order > 0) {
            s.value = value;
            s.near = near;
            s.class_ = class_;
            s.tied = 0;
        } else if (order == 0) {
            s.tied = 1;
        }
    }
    state.data[i] = s;
}
