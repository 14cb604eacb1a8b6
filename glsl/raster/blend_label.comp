#version 460
// Label rendering: the argmax over the one-hot vectors of each Gaussian's class, SEM_CHUNK
// classes per dispatch (chunk_base selects which), kept per pixel between dispatches.
#include "shared_constants.glsl"
#define CHUNK_CHANNELS SEM_CHUNK
#define LABEL_ARGMAX
#include "blend_body.glsl"
