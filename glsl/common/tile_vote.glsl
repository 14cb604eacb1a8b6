// Whether every invocation of the workgroup is done: one vote per subgroup, then a count in
// shared memory. Call from uniform control flow; two calls need a barrier between them
// (the per-tile loops have one after each batch).
#ifndef TILE_VOTE_GLSL
#define TILE_VOTE_GLSL

#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require

shared uint tile_vote_done_subgroups;

bool workgroup_all_done(bool done) {
    if (gl_LocalInvocationIndex == 0) {
        tile_vote_done_subgroups = 0;
    }
    barrier();
    if (subgroupAll(done) && subgroupElect()) {
        atomicAdd(tile_vote_done_subgroups, 1);
    }
    barrier();
    return tile_vote_done_subgroups == gl_NumSubgroups;
}

#endif
