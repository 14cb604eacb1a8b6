// Push constants of projection (project*.comp) and its backward (project_backward.comp).
#ifndef PROJECT_PARAMS_GLSL
#define PROJECT_PARAMS_GLSL

layout(push_constant) uniform ProjectParams {
    vec4 world_to_camera[3]; // rows (R00 R01 R02 t0), (R10 R11 R12 t1), (R20 R21 R22 t2)
    vec4 intrinsics;         // fx fy cx cy: the projection helpers take them together
    vec3 camera_center;      // world space: view directions for SH start here
    float near;              // Gaussians with center depth <= near or >= far are culled
    float far;
    uint width;
    uint height;
    uint n;
    uint sh_degree;
    uint sh_coeffs;          // SH coefficients stored per Gaussian (per color channel); 0: no colour
} pc;

#endif
