// One bounce of photon tracing after Embree found the hits (workers/photons.py drives the loop).
// For every hit: record it if the surface is diffuse (element, element barycentrics, weight),
// play Russian roulette on the albedo, and sample the next direction: cosine lobe (diffuse),
// mirror, or normalised Phong lobe (glossy). Double precision throughout (PoCL CPU has fp64).
// NumPy twin: kernels/scatter.py::scatter_reference. Formulas are documented there.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#include "philox.cl"

#define KIND_DIFFUSE 0
#define KIND_MIRROR 1
#define KIND_GLOSSY 2
#define PARITY_BIT 0x40000000u
#define DIRECT_BIT 0x80000000u

// Duff et al., "Building an orthonormal basis, revisited", JCGT 6(1), 2017.
inline double3 around(double3 axis, double cos_t, double phi) {
    double sign = axis.z >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sign + axis.z);
    double b = axis.x * axis.y * a;
    double3 t = (double3)(1.0 + sign * axis.x * axis.x * a, sign * b, -sign * axis.x);
    double3 bt = (double3)(b, sign + axis.y * axis.y * a, -axis.y);
    double sin_t = sqrt(clamp(1.0 - cos_t * cos_t, 0.0, 1.0));
    double c;
    const double s = sincos(phi, &c);
    return t * (sin_t * c) + bt * (sin_t * s) + axis * cos_t;
}

__kernel void scatter(
    const int depth, const uint key0, const uint key1, const double epsilon,
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
    // The launch is padded to whole work-groups with harmless rows (the wrapper pads the inputs):
    // no early return, and selects instead of branches, so PoCL can vectorise the work-group loop.
    const size_t i = get_global_id(0);
    const int t = tri[i];
    const int m = tri_mat[t];
    const int kind = mat_kind[m];
    const double u = (double)hit_u[i], v = (double)hit_v[i];
    __global const float *c = corners + 9 * (size_t)t;
    const double3 c0 = (double3)(c[0], c[1], c[2]);
    const double3 c1 = (double3)(c[3], c[4], c[5]);
    const double3 c2 = (double3)(c[6], c[7], c[8]);
    const double3 p = (1.0 - u - v) * c0 + u * c1 + v * c2;
    const double3 n = (double3)(normals[3 * t], normals[3 * t + 1], normals[3 * t + 2]);
    const double3 d = (double3)(dir_in[3 * i], dir_in[3 * i + 1], dir_in[3 * i + 2]);
    const double3 facing = dot(n, d) < 0.0 ? n : -n;
    double3 beta = (double3)(beta_in[3 * i], beta_in[3 * i + 1], beta_in[3 * i + 2]);
    const long ph = photon[i];

    // Record a diffuse hit: locate the element (ElementMesh.locate) and its barycentrics
    const int is_diffuse = kind == KIND_DIFFUSE;
    const long ns = tri_n[t];
    const double x = fmin(fmax(u, 0.0), 1.0) * (double)ns;
    const double y = fmin(fmax(v, 0.0), 1.0) * (double)ns;
    const long a = min(max((long)floor(x), 0L), ns - 1);
    const long b = min(max((long)floor(y), 0L), ns - 1 - a);
    const double fx = x - (double)a, fy = y - (double)b;
    const int up = (fx + fy <= 1.0) || (a + b >= ns - 1);
    const long cell = up ? a * ns - a * (a - 1) / 2 + b
                         : ns * (ns + 1) / 2 + a * (ns - 1) - a * (a - 1) / 2 + b;
    const double b1 = fmin(fmax(up ? fx : fx + fy - 1.0, 0.0), 1.0);
    const double b2 = fmin(fmax(up ? fy : 1.0 - fx, 0.0), 1.0 - b1);
    uint k = (uint)(tri_offset[t] + cell);
    k |= (ph & 1L) ? PARITY_BIT : 0u;
    k |= depth == 0 ? DIRECT_BIT : 0u;
    rec_key[i] = is_diffuse ? k : 0u;
    rec_bary[2 * i] = is_diffuse ? (ushort)rint(b1 * 65535.0) : (ushort)0;
    rec_bary[2 * i + 1] = is_diffuse ? (ushort)rint(b2 * 65535.0) : (ushort)0;
    rec_energy[3 * i] = is_diffuse ? (float)beta.x : 0.0f;
    rec_energy[3 * i + 1] = is_diffuse ? (float)beta.y : 0.0f;
    rec_energy[3 * i + 2] = is_diffuse ? (float)beta.z : 0.0f;
    recorded[i] = (uchar)is_diffuse;

    // Russian roulette on the albedo: survive with q = max channel, reweight by albedo / q
    const uint4 w = philox4x32_10((uint4)((uint)ph, (uint)(ph >> 32), (uint)depth, 0u), (uint2)(key0, key1));
    const double3 rho = (double3)(albedo[3 * m], albedo[3 * m + 1], albedo[3 * m + 2]);
    const double q = fmax(rho.x, fmax(rho.y, rho.z));
    int survive = philox_uniform(w.x) < q;
    beta = beta * rho / (q > 0.0 ? q : 1.0);

    // Next direction: cosine lobe about the facing normal, mirror, or Phong lobe about the mirror
    const double3 mirror = d - 2.0 * dot(d, facing) * facing;
    const double u1 = philox_uniform(w.y), u2 = philox_uniform(w.z);
    const int is_glossy = kind == KIND_GLOSSY;
    const double e = mat_exp[m];
    const double cos_t = is_glossy ? pow(u1, 1.0 / (e + 1.0)) : sqrt(1.0 - u1);
    const double3 axis = is_diffuse ? facing : mirror;
    const double3 lobe = around(axis, cos_t, 2.0 * M_PI * u2);
    const double3 nd = kind == KIND_MIRROR ? mirror : lobe;
    const double cos_o = dot(nd, facing);
    beta = is_glossy ? beta * (fmax(cos_o, 0.0) * (e + 2.0) / (e + 1.0)) : beta;
    survive = survive && (!is_glossy || cos_o > 0.0);
    const double side = dot(n, nd) < 0.0 ? -1.0 : 1.0;
    const double3 o = p + n * (side * epsilon);
    origin_out[3 * i] = (float)o.x; origin_out[3 * i + 1] = (float)o.y; origin_out[3 * i + 2] = (float)o.z;
    dir_out[3 * i] = (float)nd.x; dir_out[3 * i + 1] = (float)nd.y; dir_out[3 * i + 2] = (float)nd.z;
    beta_out[3 * i] = beta.x; beta_out[3 * i + 1] = beta.y; beta_out[3 * i + 2] = beta.z;
    alive[i] = (uchar)survive;
}
