// Shared by the rasterizer kernels and src/render/: tile size, the frame status layout, and
// the per-Gaussian math of classic 3DGS as gsplat 1.5 does it (docs/CONVENTIONS.md, Rendering).
#ifndef RASTER_COMMON_GLSL
#define RASTER_COMMON_GLSL

#include "shared_constants.glsl" // TILE_SIZE, SEM_CHUNK, the frame status words ST_*

#define TILE_PIXELS (TILE_SIZE * TILE_SIZE)
#define ALPHA_MIN (1.0 / 255.0)
#define ALPHA_MAX 0.999
#define T_MIN 1e-4
#define TWO_PI 6.28318530717958648

float sigmoid(float x) {
    return 1.0 / (1.0 + exp(-x));
}

// Offset of a 2D mean, stored as integer part plus fraction (project_body.glsl), from the
// center of pixel `pixel`: the exact integer difference first keeps full precision.
vec2 pixel_offset(vec2 mean_int, vec2 mean_frac, vec2 pixel) {
    return (mean_int - pixel) + (mean_frac - 0.5);
}

// The Gaussian's exponent at offset d: alpha = opacity * exp(-sigma). Forward, backward and
// fusion call this one function, so they agree on every skip decision.
float conic_sigma(vec3 con, vec2 d) {
    return 0.5 * (con.x * d.x * d.x + con.z * d.y * d.y) + con.y * d.x * d.y;
}

// Real spherical harmonics up to degree 3 with the standard 3DGS constants and basis
// order. coeff(k) returns the RGB coefficient k; dir is unit length.
#define SH_C0 0.28209479177387814
#define SH_C1 0.4886025119029199
#define SH_EVAL(result, degree, dir, coeff)                                                   \
    {                                                                                         \
        result = SH_C0 * coeff(0);                                                            \
        if (degree >= 1) {                                                                    \
            float x = dir.x, y = dir.y, z = dir.z;                                            \
            result += SH_C1 * (-y * coeff(1) + z * coeff(2) - x * coeff(3));                  \
            if (degree >= 2) {                                                                \
                float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z; \
                result += 1.0925484305920792 * xy * coeff(4)                                  \
                        - 1.0925484305920792 * yz * coeff(5)                                  \
                        + 0.31539156525252005 * (2.0 * zz - xx - yy) * coeff(6)               \
                        - 1.0925484305920792 * xz * coeff(7)                                  \
                        + 0.5462742152960396 * (xx - yy) * coeff(8);                          \
                if (degree >= 3) {                                                            \
                    result += -0.5900435899266435 * y * (3.0 * xx - yy) * coeff(9)            \
                            + 2.890611442640554 * xy * z * coeff(10)                          \
                            - 0.4570457994644658 * y * (4.0 * zz - xx - yy) * coeff(11)       \
                            + 0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * coeff(12) \
                            - 0.4570457994644658 * x * (4.0 * zz - xx - yy) * coeff(13)       \
                            + 1.445305721320277 * z * (xx - yy) * coeff(14)                   \
                            - 0.5900435899266435 * x * (xx - 3.0 * yy) * coeff(15);           \
                }                                                                             \
            }                                                                                 \
        }                                                                                     \
    }

#endif
