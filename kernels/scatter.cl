// One bounce of photon tracing after Embree found the hits (pipeline/photons/tracing.py drives the loop).
// For every hit: record it if the surface is diffuse (element, element barycentrics, weight),
// play Russian roulette on the albedo, and sample the next direction: cosine lobe (diffuse),
// mirror, normalised Phong lobe (glossy), or Fresnel's choice of mirror and refraction (dielectric).
// Double precision throughout (PoCL CPU has fp64).
// NumPy twin: kernels/scatter.py::scatter_reference; formulas are documented there.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "philox.cl"
#include "lanes.cl"

#define KIND_DIFFUSE 0
#define KIND_MIRROR 1
#define KIND_GLOSSY 2
#define KIND_DIELECTRIC 3
// PARITY_BIT, DIRECT_BIT, BARY_SCALE: build options from kernels/record_layout.py (kernels/context.py)

// Eight rays a work item, written on double8/long8/uint8 so that it runs in SIMD whatever the
// compiler decides: PoCL's implicit work-group vectoriser gave up on the scalar version of this
// kernel (its SLP pass packs x/y pairs first, and libm calls stop it), which then cost 3x as much.
// Lane l of work item g is ray min(8 g + l, count - 1); past the end, lanes repeat the last ray and
// write the same values. sin/cos come from polynomials (sincos8; twin sampling.py::sincos_poly) and
// the Phong lobe's u^(1/(e+1)) from the host (scatter.py::glossy_cos), so that no libm call can
// differ from the NumPy twin's.
__kernel void scatter8(
    const long count, const int depth, const uint key0, const uint key1, const double epsilon,
    __global const int *tri, __global const float *hit_u, __global const float *hit_v,
    __global const float *dir_in, __global const double *beta_in, __global const long *photon,
    __global const double *glossy_cos, __global const double *albedo, __global const double *shading,
    __global const int *hit_kind, __global const double *hit_exp, __global const double *hit_ior,
    __global const float *corners, __global const double *normals,
    __global const int *tri_n, __global const long *tri_offset,
    __global uint *rec_key, __global ushort *rec_bary, __global float *rec_energy,
    __global uchar *recorded,
    __global float *origin_out, __global float *dir_out, __global double *beta_out,
    __global uchar *alive)
{
    const long8 i = min((long8)(8 * (long)get_global_id(0)) + (long8)(0, 1, 2, 3, 4, 5, 6, 7),
                        (long8)(count - 1));
    const long8 tri_i = convert_long8(G8(int8, tri, i));
    const long8 hit = tri_i >= 0L;  // a miss (-1) records nothing and ends its path
    const long8 t = select((long8)(0), tri_i, hit);
    const long8 kind = convert_long8(G8(int8, hit_kind, i));
    const double8 u = convert_double8(G8(float8, hit_u, i)), v = convert_double8(G8(float8, hit_v, i));
    const double8 w0 = 1.0 - u - v;
    const long8 c9 = 9 * t;
    const double8 px = w0 * convert_double8(G8(float8, corners, c9)) + u * convert_double8(G8(float8, corners, c9 + 3))
                     + v * convert_double8(G8(float8, corners, c9 + 6));
    const double8 py = w0 * convert_double8(G8(float8, corners, c9 + 1)) + u * convert_double8(G8(float8, corners, c9 + 4))
                     + v * convert_double8(G8(float8, corners, c9 + 7));
    const double8 pz = w0 * convert_double8(G8(float8, corners, c9 + 2)) + u * convert_double8(G8(float8, corners, c9 + 5))
                     + v * convert_double8(G8(float8, corners, c9 + 8));
    const double8 nx = G8(double8, normals, 3 * t), ny = G8(double8, normals, 3 * t + 1),
                  nz = G8(double8, normals, 3 * t + 2);
    const double8 dx = convert_double8(G8(float8, dir_in, 3 * i)), dy = convert_double8(G8(float8, dir_in, 3 * i + 1)),
                  dz = convert_double8(G8(float8, dir_in, 3 * i + 2));
    // Sidedness from the geometric normal, lobes about the shading normal (per hit, from the host)
    const double8 fs = select((double8)(-1.0), (double8)(1.0), nx * dx + ny * dy + nz * dz < 0.0);
    const double8 fx_ = fs * G8(double8, shading, 3 * i), fy_ = fs * G8(double8, shading, 3 * i + 1),
                  fz_ = fs * G8(double8, shading, 3 * i + 2);
    double8 bx = G8(double8, beta_in, 3 * i), by = G8(double8, beta_in, 3 * i + 1), bz = G8(double8, beta_in, 3 * i + 2);
    const long8 ph = G8(long8, photon, i);

    // Record a diffuse hit: locate the element (ElementMesh.locate) and its barycentrics
    const long8 is_diffuse = hit & (kind == (long8)(KIND_DIFFUSE));
    double8 b1, b2;
    const long8 element = locate8(convert_long8(G8(int8, tri_n, t)), G8(long8, tri_offset, t), u, v, &b1, &b2);
    ulong8 k = convert_ulong8(element) & 0xFFFFFFFFUL;
    k |= select((ulong8)(0), (ulong8)(PARITY_BIT), (ph & 1L) != 0L);
    k |= (ulong8)(depth == 0 ? DIRECT_BIT : 0u);
    k = select((ulong8)(0), k, is_diffuse);
    S8(rec_key, i, convert_uint8(k));
    const ushort8 q1 = convert_ushort8(select((double8)(0.0), rint(b1 * BARY_SCALE), is_diffuse));
    const ushort8 q2 = convert_ushort8(select((double8)(0.0), rint(b2 * BARY_SCALE), is_diffuse));
    S8(rec_bary, 2 * i, q1);
    S8(rec_bary, 2 * i + 1, q2);
    S8(rec_energy, 3 * i, convert_float8(select((double8)(0.0), bx, is_diffuse)));
    S8(rec_energy, 3 * i + 1, convert_float8(select((double8)(0.0), by, is_diffuse)));
    S8(rec_energy, 3 * i + 2, convert_float8(select((double8)(0.0), bz, is_diffuse)));
    S8(recorded, i, convert_uchar8(-is_diffuse));

    // Philox words of counter (photon, depth) under key (seed, frame): roulette, two for the direction
    uint8 r0 = convert_uint8(ph & 0xFFFFFFFFL), r1 = convert_uint8(ph >> 32), r2 = (uint8)((uint)depth), r3 = (uint8)(0u);
    PHILOX8_10(r0, r1, r2, r3, key0, key1);

    // Russian roulette on the albedo: survive with q = max channel, reweight by albedo / q
    const double8 ax = G8(double8, albedo, 3 * i), ay = G8(double8, albedo, 3 * i + 1), az = G8(double8, albedo, 3 * i + 2);
    const double8 q = fmax(ax, fmax(ay, az));
    long8 survive = uniform8(r0) < q;
    const double8 qs = select((double8)(1.0), q, q > 0.0);
    bx = bx * ax / qs; by = by * ay / qs; bz = bz * az / qs;

    // Next direction: cosine lobe about the facing normal, mirror, or Phong lobe about the mirror
    const double8 dn = dx * fx_ + dy * fy_ + dz * fz_;
    const double8 mx = dx - 2.0 * dn * fx_, my = dy - 2.0 * dn * fy_, mz = dz - 2.0 * dn * fz_;
    const double8 u1 = uniform8(r1), u2 = uniform8(r2);
    const long8 is_glossy = kind == (long8)(KIND_GLOSSY);
    const double8 e = G8(double8, hit_exp, i);
    const double8 cos_t = select(sqrt(1.0 - u1), G8(double8, glossy_cos, select((long8)(0), i, is_glossy)), is_glossy);
    const double8 zx = select(mx, fx_, is_diffuse), zy = select(my, fy_, is_diffuse), zz = select(mz, fz_, is_diffuse);
    double8 lx, ly, lz;
    around8(zx, zy, zz, cos_t, 2.0 * M_PI * u2, &lx, &ly, &lz);
    const long8 is_mirror = kind == (long8)(KIND_MIRROR);
    // Solid glass: Fresnel's share reflects, the rest refracts by Snell's law (u1 decides); entering
    // where the geometric normal faces the ray (eta = n1 / n2 = 1 / ior), leaving elsewhere
    const long8 is_dielectric = kind == (long8)(KIND_DIELECTRIC);
    const double8 ior = G8(double8, hit_ior, i);
    const double8 eta = select(ior, 1.0 / ior, fs > 0.0);
    const double8 cos_i = fmin(-dn, 1.0);
    const double8 sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    const long8 tir = sin2_t >= 1.0;
    const double8 cos_tr = sqrt(fmax(1.0 - sin2_t, 0.0));
    const double8 rs = (eta * cos_i - cos_tr) / (eta * cos_i + cos_tr);
    const double8 rp = (eta * cos_tr - cos_i) / (eta * cos_tr + cos_i);
    const double8 fresnel = select(0.5 * (rs * rs + rp * rp), (double8)(1.0), tir);
    const long8 refracts = is_dielectric & (u1 >= fresnel);
    const double8 kt = eta * cos_i - cos_tr;
    const long8 mirrors = is_mirror | (is_dielectric & ~refracts);
    const double8 ox = select(select(lx, mx, mirrors), eta * dx + kt * fx_, refracts);
    const double8 oy = select(select(ly, my, mirrors), eta * dy + kt * fy_, refracts);
    const double8 oz = select(select(lz, mz, mirrors), eta * dz + kt * fz_, refracts);
    const double8 cos_o = ox * fx_ + oy * fy_ + oz * fz_;
    const double8 gw = select((double8)(1.0), fmax(cos_o, 0.0) * (e + 2.0) / (e + 1.0), is_glossy);
    bx *= gw; by *= gw; bz *= gw;
    survive = survive & (~is_glossy | (cos_o > 0.0));
    const double8 n_out = nx * ox + ny * oy + nz * oz;
    // leaves on the side it arrived from, or the other side where it refracts
    survive = survive & select(n_out * fs > 0.0, n_out * fs < 0.0, refracts);
    const double8 off = surface_offset8(corners, c9, epsilon);
    const double8 side = select(off, -off, n_out < 0.0);
    S8(origin_out, 3 * i, convert_float8(px + nx * side));
    S8(origin_out, 3 * i + 1, convert_float8(py + ny * side));
    S8(origin_out, 3 * i + 2, convert_float8(pz + nz * side));
    S8(dir_out, 3 * i, convert_float8(ox));
    S8(dir_out, 3 * i + 1, convert_float8(oy));
    S8(dir_out, 3 * i + 2, convert_float8(oz));
    S8(beta_out, 3 * i, bx);
    S8(beta_out, 3 * i + 1, by);
    S8(beta_out, 3 * i + 2, bz);
    S8(alive, i, convert_uchar8(-(survive & hit)));
}
