#version 460
// Median depth only: per pixel, the depth of the Gaussian that takes its transmittance below
// one half (0 where it never falls that far), for occlusion tests of Gaussian centers
// (fuse/center_pixel.comp). Each pixel stops at that Gaussian, not at saturation, so this
// walks a fraction of the lists full blending does.
#define CHUNK_CHANNELS 0
#define MEDIAN_DEPTH
#include "blend_body.glsl"
