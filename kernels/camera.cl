// Camera rays with pixel jitter, eight samples a work item: sample c (counter c0 + i) of pixel
// c / spp is jittered by a splitmix64 hash of (frame key, c) and cast through the pinhole camera
// (looking down -Z, +Y up, yfov vertical). NumPy twin: kernels/camera.py::camera_rays_reference
// (the compositor's random numbers, pipeline/frames/random_numbers.py, dimension 0).
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "lanes.cl"

inline ulong8 mix64_8(ulong8 x) {  // splitmix64 finaliser
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9UL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBUL;
    return x ^ (x >> 31);
}

__kernel void camera8(const long c0, const long count, const ulong key, const int width,
                      const int height, const int spp, const double scale_x, const double tan_y,
                      const float r00, const float r01, const float r02, const float r10,
                      const float r11, const float r12, const float r20, const float r21,
                      const float r22, __global float *dir_out)
{
    const long8 i = min((long8)(8 * (long)get_global_id(0)) + (long8)(0, 1, 2, 3, 4, 5, 6, 7),
                        (long8)(count - 1));
    const long8 counter = c0 + i;
    const ulong8 h = mix64_8(mix64_8(convert_ulong8(counter) ^ key));  // dimension 0 adds nothing
    const double8 jx = convert_double8(h >> 32) * (1.0 / 4294967296.0);
    const double8 jy = convert_double8(h & 0xFFFFFFFFUL) * (1.0 / 4294967296.0);
    // Pixel row and column by exact double division (counters < 2^40, far below 2^53): 64-bit
    // integer division has no SIMD instruction and would make the lanes scalar.
    const double8 pixel = floor(convert_double8(counter) / (double)spp);
    const double8 row = floor(pixel / (double)width);
    const double8 px = (pixel - row * (double)width) + jx;
    const double8 py = row + jy;
    const float8 x = convert_float8(((2.0 / width) * px - 1.0) * scale_x);
    const float8 y = convert_float8((1.0 - (2.0 / height) * py) * tan_y);
    float8 dx = x * r00 + y * r01 - r02;
    float8 dy = x * r10 + y * r11 - r12;
    float8 dz = x * r20 + y * r21 - r22;
    const float8 norm = sqrt(dx * dx + dy * dy + dz * dz);
    S8(dir_out, 3 * i, dx / norm);
    S8(dir_out, 3 * i + 1, dy / norm);
    S8(dir_out, 3 * i + 2, dz / norm);
}
