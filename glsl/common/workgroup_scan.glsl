// Workgroup-wide scans built from subgroup scans; correct for any subgroup size from 4 to
// 128 lanes. Element order is the "lane order" t = gl_SubgroupID * gl_SubgroupSize +
// gl_SubgroupInvocationID, a bijection onto the workgroup because every pipeline whose
// width is a multiple of the subgroup size is built with REQUIRE_FULL_SUBGROUPS.
//
// The includer defines WG_SIZE before including this file, and calls these functions from
// uniform control flow (they contain barriers).
#ifndef WORKGROUP_SCAN_GLSL
#define WORKGROUP_SCAN_GLSL

#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require

// Subgroups of at least 4 lanes: at most WG_SIZE / 4 subgroups.
#define WG_MAX_SUBGROUPS (WG_SIZE / 4)

shared uint wg_scan_partials[WG_MAX_SUBGROUPS];
shared uint wg_scan_total;

uint lane_order_index() {
    return gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
}

// Exclusive prefix sum of v over the workgroup in lane order; `total` gets the sum.
uint workgroup_exclusive_add(uint v, out uint total) {
    uint inclusive = subgroupInclusiveAdd(v);
    if (gl_SubgroupInvocationID == gl_SubgroupSize - 1) {
        wg_scan_partials[gl_SubgroupID] = inclusive;
    }
    barrier();
    // At most WG_MAX_SUBGROUPS entries: a short serial pass is cheaper than a second level.
    if (gl_LocalInvocationIndex == 0) {
        uint acc = 0;
        for (uint s = 0; s < gl_NumSubgroups; s++) {
            uint x = wg_scan_partials[s];
            wg_scan_partials[s] = acc;
            acc += x;
        }
        wg_scan_total = acc;
    }
    barrier();
    uint result = wg_scan_partials[gl_SubgroupID] + inclusive - v;
    total = wg_scan_total;
    barrier(); // the scratch may be reused right after
    return result;
}

// Sum of v over the workgroup, valid in every invocation.
uint workgroup_add(uint v) {
    uint total;
    workgroup_exclusive_add(v, total);
    return total;
}

#endif
