#version 460
// Depths only: per pixel, the median depth (of the Gaussian that takes its transmittance
// below one half) and the opaque depth (below OPAQUE_T), 0 where it never falls that far,
// for occlusion tests of Gaussian centers (fuse/center_pixel.comp). Each pixel stops at
// the opaque depth, not at saturation, so this walks a fraction of the lists full blending
// does.
#define CHUNK_CHANNELS 0
#define MEDIAN_DEPTH
#include "blend_body.glsl"
