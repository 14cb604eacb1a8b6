// Arrays that grow with the input (per Gaussian, or per pixel of a training image) and
// that a kernel indexes beyond what a chunk or band could bound (the Gaussian ids of tile
// lists, a whole scene or image in one dispatch) are reached by buffer device address, not
// through a binding: one binding is capped at maxStorageBufferRange (128 MiB on lavapipe:
// 8.4M Gaussians of 16 bytes, 3.3M of the 40-byte screen-space gradient), an address only
// by the buffer (one allocation) and the signed 32-bit index. The host passes each array's
// address in the kernel's push constants as a uvec2 (`Buffer::address_words`, which checks
// the index bound), and the includer names the array with a macro, e.g.
// `#define conics Vec4Array(pc.conics_addr)`, so the kernel body indexes it like a bound
// buffer (`conics.data[g]`).
#ifndef ADDRESSED_ARRAYS_GLSL
#define ADDRESSED_ARRAYS_GLSL
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer Vec4Array { vec4 data[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer UVec4Array { uvec4 data[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer Vec2Array { vec2 data[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer UVec2Array { uvec2 data[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer FloatArray { float data[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer UintArray { uint data[]; };
// Arrays kernels write (gradient sums, often atomically).
layout(buffer_reference, std430, buffer_reference_align = 4) buffer FloatArrayRW { float data[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) buffer UintArrayRW { uint data[]; };
// Written by some invocations while others of the same dispatch read it (lock-free
// union-find links): every access goes to memory, none is cached.
layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer UintArrayCoherent { uint data[]; };

#endif
