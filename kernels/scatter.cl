// One bounce of photon tracing after Embree found the hits (workers/photons.py drives the loop).
// For every hit: record it if the surface is diffuse (element, element barycentrics, weight),
// play Russian roulette on the albedo, and sample the next direction: cosine lobe (diffuse),
// mirror, or normalised Phong lobe (glossy). Double precision throughout (PoCL CPU has fp64).
// NumPy twin: kernels/scatter.py::scatter_reference; formulas are documented there.
//
// Written with scalars only (no double3/uint4) and selects instead of branches.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "philox.cl"
#include "sampling.cl"

#define KIND_DIFFUSE 0
#define KIND_MIRROR 1
#define KIND_GLOSSY 2
#define PARITY_BIT 0x40000000u
#define DIRECT_BIT 0x80000000u

__kernel void scatter(
    const long count, const int depth, const uint key0, const uint key1, const double epsilon,
    __global const int *tri, __global const float *hit_u, __global const float *hit_v,
    __global const float *dir_in, __global const double *beta_in, __global const long *photon,
    __global const float *corners, __global const double *normals, __global const int *tri_mat,
    __global const int *tri_n, __global const long *tri_offset,
    __global const double *albedo, __global const int *mat_kind, __global const double *mat_exp,
    __global uint *rec_key, __global ushort *rec_bary, __global float *rec_energy,
    __global uchar *recorded,
    __global float *origin_out, __global float *dir_out, __global double *beta_out,
    __global uchar *alive)
{
    // Launched on whole work-groups: the items past the end repeat the last row, writing the same
    // values to the same places, which needs neither padding copies nor a branch.
    const size_t i = min((long)get_global_id(0), count - 1);
    const int hit = tri[i] >= 0;  // a miss (-1) records nothing and ends its path
    const int t = hit ? tri[i] : 0;
    const int m = tri_mat[t];
    const int kind = mat_kind[m];
    const double u = (double)hit_u[i], v = (double)hit_v[i];
    const double w0 = 1.0 - u - v;
    const size_t c9 = 9 * (size_t)t;
    const double px = w0 * corners[c9] + u * corners[c9 + 3] + v * corners[c9 + 6];
    const double py = w0 * corners[c9 + 1] + u * corners[c9 + 4] + v * corners[c9 + 7];
    const double pz = w0 * corners[c9 + 2] + u * corners[c9 + 5] + v * corners[c9 + 8];
    const double nx = normals[3 * t], ny = normals[3 * t + 1], nz = normals[3 * t + 2];
    const double dx = dir_in[3 * i], dy = dir_in[3 * i + 1], dz = dir_in[3 * i + 2];
    const double fs = nx * dx + ny * dy + nz * dz < 0.0 ? 1.0 : -1.0;  // normal facing the ray
    const double fx_ = fs * nx, fy_ = fs * ny, fz_ = fs * nz;
    double bx = beta_in[3 * i], by = beta_in[3 * i + 1], bz = beta_in[3 * i + 2];
    const long ph = photon[i];

    // Record a diffuse hit: locate the element (ElementMesh.locate) and its barycentrics
    const int is_diffuse = hit && kind == KIND_DIFFUSE;
    const long ns = tri_n[t];
    const double x = fmin(fmax(u, 0.0), 1.0) * (double)ns;
    const double y = fmin(fmax(v, 0.0), 1.0) * (double)ns;
    const long a = min(max((long)floor(x), 0L), ns - 1);
    const long b = min(max((long)floor(y), 0L), ns - 1 - a);
    const double ex = x - (double)a, ey = y - (double)b;
    const int up = (ex + ey <= 1.0) || (a + b >= ns - 1);
    const long cell = up ? a * ns - a * (a - 1) / 2 + b
                         : ns * (ns + 1) / 2 + a * (ns - 1) - a * (a - 1) / 2 + b;
    const double b1 = fmin(fmax(up ? ex : ex + ey - 1.0, 0.0), 1.0);
    const double b2 = fmin(fmax(up ? ey : 1.0 - ex, 0.0), 1.0 - b1);
    uint k = (uint)(tri_offset[t] + cell);
    k |= (ph & 1L) ? PARITY_BIT : 0u;
    k |= depth == 0 ? DIRECT_BIT : 0u;
    rec_key[i] = is_diffuse ? k : 0u;
    rec_bary[2 * i] = is_diffuse ? (ushort)rint(b1 * 65535.0) : (ushort)0;
    rec_bary[2 * i + 1] = is_diffuse ? (ushort)rint(b2 * 65535.0) : (ushort)0;
    rec_energy[3 * i] = is_diffuse ? (float)bx : 0.0f;
    rec_energy[3 * i + 1] = is_diffuse ? (float)by : 0.0f;
    rec_energy[3 * i + 2] = is_diffuse ? (float)bz : 0.0f;
    recorded[i] = (uchar)is_diffuse;

    // Philox words of counter (photon, depth) under key (seed, frame): roulette, two for the direction
    uint r0 = (uint)ph, r1 = (uint)(ph >> 32), r2 = (uint)depth, r3 = 0u;
    PHILOX4X32_10(r0, r1, r2, r3, key0, key1);

    // Russian roulette on the albedo: survive with q = max channel, reweight by albedo / q
    const double ax = albedo[3 * m], ay = albedo[3 * m + 1], az = albedo[3 * m + 2];
    const double q = fmax(ax, fmax(ay, az));
    int survive = philox_uniform(r0) < q;
    const double qs = q > 0.0 ? q : 1.0;
    bx = bx * ax / qs; by = by * ay / qs; bz = bz * az / qs;

    // Next direction: cosine lobe about the facing normal, mirror, or Phong lobe about the mirror
    const double dn = dx * fx_ + dy * fy_ + dz * fz_;
    const double mx = dx - 2.0 * dn * fx_, my = dy - 2.0 * dn * fy_, mz = dz - 2.0 * dn * fz_;
    const double u1 = philox_uniform(r1), u2 = philox_uniform(r2);
    const int is_glossy = kind == KIND_GLOSSY;
    const double e = mat_exp[m];
    const double cos_t = is_glossy ? pow(u1, 1.0 / (e + 1.0)) : sqrt(1.0 - u1);
    // The lobe's axis: the facing normal (diffuse) or the mirror direction (glossy)
    const double zx = is_diffuse ? fx_ : mx, zy = is_diffuse ? fy_ : my, zz = is_diffuse ? fz_ : mz;
    double lx, ly, lz;
    around(zx, zy, zz, cos_t, 2.0 * M_PI * u2, &lx, &ly, &lz);
    const int is_mirror = kind == KIND_MIRROR;
    const double ox = is_mirror ? mx : lx, oy = is_mirror ? my : ly, oz = is_mirror ? mz : lz;
    const double cos_o = ox * fx_ + oy * fy_ + oz * fz_;
    const double gw = is_glossy ? fmax(cos_o, 0.0) * (e + 2.0) / (e + 1.0) : 1.0;
    bx *= gw; by *= gw; bz *= gw;
    survive = survive && (!is_glossy || cos_o > 0.0);
    const double side = nx * ox + ny * oy + nz * oz < 0.0 ? -epsilon : epsilon;
    origin_out[3 * i] = (float)(px + nx * side);
    origin_out[3 * i + 1] = (float)(py + ny * side);
    origin_out[3 * i + 2] = (float)(pz + nz * side);
    dir_out[3 * i] = (float)ox; dir_out[3 * i + 1] = (float)oy; dir_out[3 * i + 2] = (float)oz;
    beta_out[3 * i] = bx; beta_out[3 * i + 1] = by; beta_out[3 * i + 2] = bz;
    alive[i] = (uchar)(survive && hit);
}
