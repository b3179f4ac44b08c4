// Photon emission: pick an emitter by power (binary search in the CDF) and sample an origin, a
// direction and an RGB weight. NumPy twin and formulas: kernels/emit.py::emit_reference.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "philox.cl"
#include "sampling.cl"

#define EMIT_POINT 0
#define EMIT_SPOT 1
#define EMIT_DIRECTIONAL 2
#define EMIT_AREA 3
#define EMISSION_STREAM 0xFFFF0000u

__kernel void emit(
    const long count, const uint key0, const uint key1, const int n_emitters,
    const double cx, const double cy, const double cz, const double radius, const double epsilon,
    __global const long *photon,
    __global const double *cdf, __global const double *prob, __global const int *kind,
    __global const long *index, __global const double *flux,
    __global const double *light_pos, __global const double *light_dir, __global const double *light_rad,
    __global const double *cos_outer, __global const double *cos_inner,
    __global const float *corners, __global const double *normals,
    __global float *origin_out, __global float *dir_out, __global double *beta_out, __global int *emitter)
{
    const size_t i = min((long)get_global_id(0), count - 1);  // whole work-groups; see scatter.cl
    const long ph = photon[i];
    uint r0 = (uint)ph, r1 = (uint)(ph >> 32), r2 = EMISSION_STREAM, r3 = 0u;
    PHILOX4X32_10(r0, r1, r2, r3, key0, key1);
    uint s0 = (uint)ph, s1 = (uint)(ph >> 32), s2 = EMISSION_STREAM + 1u, s3 = 0u;
    PHILOX4X32_10(s0, s1, s2, s3, key0, key1);
    const double w0 = philox_uniform(r0), u1 = philox_uniform(r1), u2 = philox_uniform(r2);
    const double u3 = philox_uniform(r3), u4 = philox_uniform(s0);

    // First emitter whose CDF exceeds w0 (numpy.searchsorted side="right"), clamped to the last
    int lo = 0, hi = n_emitters;
    while (lo < hi) {
        const int mid = (lo + hi) / 2;
        if (cdf[mid] <= w0) lo = mid + 1; else hi = mid;
    }
    const int e = min(lo, n_emitters - 1);
    const int k = kind[e];
    const long src = index[e];
    double ox, oy, oz, dx, dy, dz, wr, wg, wb;
    if (k == EMIT_AREA) {
        const double su = sqrt(u1);
        const double b1 = su * (1.0 - u2), b2 = su * u2, b0 = 1.0 - b1 - b2;
        const size_t c9 = 9 * (size_t)src;
        const double nx = normals[3 * src], ny = normals[3 * src + 1], nz = normals[3 * src + 2];
        around(nx, ny, nz, sqrt(1.0 - u3), 2.0 * M_PI * u4, &dx, &dy, &dz);
        ox = b0 * corners[c9] + b1 * corners[c9 + 3] + b2 * corners[c9 + 6] + nx * epsilon;
        oy = b0 * corners[c9 + 1] + b1 * corners[c9 + 4] + b2 * corners[c9 + 7] + ny * epsilon;
        oz = b0 * corners[c9 + 2] + b1 * corners[c9 + 5] + b2 * corners[c9 + 8] + nz * epsilon;
        wr = flux[3 * e]; wg = flux[3 * e + 1]; wb = flux[3 * e + 2];
    } else {
        const double ax = light_dir[3 * src], ay = light_dir[3 * src + 1], az = light_dir[3 * src + 2];
        const double rr = light_rad[3 * src], rg = light_rad[3 * src + 1], rb = light_rad[3 * src + 2];
        ox = light_pos[3 * src]; oy = light_pos[3 * src + 1]; oz = light_pos[3 * src + 2];
        if (k == EMIT_POINT) {
            around(0.0, 0.0, 1.0, 1.0 - 2.0 * u1, 2.0 * M_PI * u2, &dx, &dy, &dz);
            const double s = 4.0 * M_PI;
            wr = rr * s; wg = rg * s; wb = rb * s;
        } else if (k == EMIT_SPOT) {
            const double co = cos_outer[src], ci = cos_inner[src];
            const double cos_t = 1.0 - u1 * (1.0 - co);
            around(ax, ay, az, cos_t, 2.0 * M_PI * u2, &dx, &dy, &dz);
            double f = fmin(fmax((cos_t - co) / (ci - co), 0.0), 1.0);
            f = f * f;
            const double s = f * (2.0 * M_PI * (1.0 - co));
            wr = rr * s; wg = rg * s; wb = rb * s;
        } else {  // directional: a disk of the scene's radius facing the light, upstream of the scene
            const double r = radius * sqrt(u1), phi = 2.0 * M_PI * u2;
            double tx, ty, tz, sx, sy, sz;
            orthonormal_basis(ax, ay, az, &tx, &ty, &tz, &sx, &sy, &sz);
            const double rc = r * cos(phi), rs = r * sin(phi), back = radius * 1.05;
            ox = cx + (tx * rc + sx * rs) - ax * back;
            oy = cy + (ty * rc + sy * rs) - ay * back;
            oz = cz + (tz * rc + sz * rs) - az * back;
            dx = ax; dy = ay; dz = az;
            const double s = M_PI * radius * radius;
            wr = rr * s; wg = rg * s; wb = rb * s;
        }
    }
    const double p = prob[e];
    origin_out[3 * i] = (float)ox; origin_out[3 * i + 1] = (float)oy; origin_out[3 * i + 2] = (float)oz;
    dir_out[3 * i] = (float)dx; dir_out[3 * i + 1] = (float)dy; dir_out[3 * i + 2] = (float)dz;
    beta_out[3 * i] = wr / p; beta_out[3 * i + 1] = wg / p; beta_out[3 * i + 2] = wb / p;
    emitter[i] = e;
}
