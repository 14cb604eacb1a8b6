// The 3DGS SSIM window: an 11-tap gaussian (sigma 1.5) normalized to sum 1, applied along
// x then y (the 2D window is its outer product). Taps past the image edge read zero, as
// the reference's conv2d with padding 5 does. The window is symmetric, so this zero-padded
// 'same' blur is its own transpose: the backward pass blurs with the same taps.
#ifndef SSIM_WINDOW_GLSL
#define SSIM_WINDOW_GLSL

#include "shared_constants.glsl" // SSIM_TILE

#extension GL_EXT_control_flow_attributes : require

#define SSIM_RADIUS 5
#define SSIM_TAPS 11

// exp(-(k - 5)^2 / (2 * 1.5^2)) / sum, evaluated in f64.
const float SSIM_WEIGHTS[SSIM_TAPS] = float[SSIM_TAPS](
    1.028380084e-03, 7.598758135e-03, 3.600077213e-02, 1.093606895e-01, 2.130055377e-01,
    2.660117249e-01,
    2.130055377e-01, 1.093606895e-01, 3.600077213e-02, 7.598758135e-03, 1.028380084e-03);

const float SSIM_C1 = 0.01 * 0.01;
const float SSIM_C2 = 0.03 * 0.03;

#endif
