// Eight lanes a work item: gathers, scatters, Philox and the sampling helpers on double8/uint8,
// for kernels that must run in SIMD whatever PoCL's implicit vectoriser decides (scatter.cl,
// emit.cl). Every operation matches its NumPy twin's order (kernels/sampling.py, philox.py).
#ifndef PHOTONLOOM_LANES_CL
#define PHOTONLOOM_LANES_CL
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#include "philox.cl"

#define PIO2_HI 1.57079632673412561417e+00
#define PIO2_LO 6.07710050650619224932e-11
#define TWO_OVER_PI 6.36619772367581382433e-01

#define G8(T, a, ix) ((T)(a[(ix).s0], a[(ix).s1], a[(ix).s2], a[(ix).s3], \
                          a[(ix).s4], a[(ix).s5], a[(ix).s6], a[(ix).s7]))
#define S8(a, ix, v) do { a[(ix).s0] = (v).s0; a[(ix).s1] = (v).s1; a[(ix).s2] = (v).s2; \
                          a[(ix).s3] = (v).s3; a[(ix).s4] = (v).s4; a[(ix).s5] = (v).s5; \
                          a[(ix).s6] = (v).s6; a[(ix).s7] = (v).s7; } while (0)

#define PHILOX8_ROUND(c0, c1, c2, c3, k0, k1) do { \
        const ulong8 p0_ = (ulong8)((ulong)PHILOX_M0) * convert_ulong8(c0); \
        const ulong8 p1_ = (ulong8)((ulong)PHILOX_M1) * convert_ulong8(c2); \
        const uint8 n0_ = convert_uint8(p1_ >> 32) ^ (c1) ^ (uint8)(k0); \
        const uint8 n2_ = convert_uint8(p0_ >> 32) ^ (c3) ^ (uint8)(k1); \
        (c1) = convert_uint8(p1_ & 0xFFFFFFFFUL); (c3) = convert_uint8(p0_ & 0xFFFFFFFFUL); \
        (c0) = n0_; (c2) = n2_; \
    } while (0)

// Self-intersection offset of the triangles at c9 (9 float corners each): epsilon times the largest
// corner magnitude, never below FLT_MIN (pipeline/photons/raycast.py says why). Twin: scatter.py::surface_offset.
inline double8 surface_offset8(__global const float *corners, const long8 c9, const double epsilon) {
    double8 s = (double8)(FLT_MIN);
    for (int j = 0; j < 9; ++j)
        s = fmax(s, fabs(convert_double8(G8(float8, corners, c9 + (long8)(j)))));
    return epsilon * s;
}

inline double8 uniform8(uint8 x) { return convert_double8(x >> 8) * (1.0 / 16777216.0); }

inline void sincos8(const double8 phi, double8 *s, double8 *c) {
    const double8 q = rint(phi * TWO_OVER_PI);
    const double8 r = (phi - q * PIO2_HI) - q * PIO2_LO;
    const double8 z = r * r;
    const double8 sr = r + (z * r) * (-1.66666666666666324348e-01 + z * (8.33333333332248946124e-03
        + z * (-1.98412698298579493134e-04 + z * (2.75573137070700676789e-06
        + z * (-2.50507602534068634195e-08 + z * 1.58969099521155010221e-10)))));
    const double8 cr = 1.0 - (0.5 * z - z * (z * (4.16666666666666019037e-02 + z * (-1.38888888888741095749e-03
        + z * (2.48015872894767294178e-05 + z * (-2.75573143513906633035e-07
        + z * (2.08757232129817482790e-09 + z * -1.13596475577881948265e-11)))))));
    const long8 quadrant = convert_long8(q) & 3L;
    *s = select(select(select(-cr, -sr, quadrant == 2L), cr, quadrant == 1L), sr, quadrant == 0L);
    *c = select(select(select(sr, -cr, quadrant == 2L), -sr, quadrant == 1L), cr, quadrant == 0L);
}


// Philox4x32-10 on eight counters at once (PHILOX4X32_10 of philox.cl, lane by lane).
#define PHILOX8_10(c0, c1, c2, c3, key0, key1) PHILOX_10(PHILOX8_ROUND, c0, c1, c2, c3, key0, key1)

// Orthonormal tangents (t, s) of unit axes z (Duff et al., JCGT 6(1), 2017), eight at a time.
inline void basis8(double8 zx, double8 zy, double8 zz, double8 *tx, double8 *ty, double8 *tz,
                   double8 *sx, double8 *sy, double8 *sz) {
    const double8 sgn = select((double8)(-1.0), (double8)(1.0), zz >= 0.0);
    const double8 ia = -1.0 / (sgn + zz);
    const double8 ib = zx * zy * ia;
    *tx = 1.0 + sgn * zx * zx * ia; *ty = sgn * ib; *tz = -sgn * zx;
    *sx = ib; *sy = sgn + zy * zy * ia; *sz = -zy;
}

// Directions at polar angle acos(cos_t) and azimuth phi about unit axes z (sampling.py::around
// with polynomial=True).
inline void around8(double8 zx, double8 zy, double8 zz, double8 cos_t, double8 phi,
                    double8 *ox, double8 *oy, double8 *oz) {
    double8 tx, ty, tz, sx, sy, sz;
    basis8(zx, zy, zz, &tx, &ty, &tz, &sx, &sy, &sz);
    const double8 sin_t = sqrt(fmin(fmax(1.0 - cos_t * cos_t, 0.0), 1.0));
    double8 sp, cp;
    sincos8(phi, &sp, &cp);
    *ox = tx * (sin_t * cp) + sx * (sin_t * sp) + zx * cos_t;
    *oy = ty * (sin_t * cp) + sy * (sin_t * sp) + zy * cos_t;
    *oz = tz * (sin_t * cp) + sz * (sin_t * sp) + zz * cos_t;
}

// The element of hits at Embree barycentrics (u, v) on source triangles split ns x ns, and the
// hit's barycentrics (b1, b2) of the element's vertices 1 and 2 (pipeline/scene/elements.py,
// locate_in_triangles: the same arithmetic).
inline long8 locate8(const long8 ns, const long8 offset, const double8 u, const double8 v,
                     double8 *b1, double8 *b2) {
    const double8 x = fmin(fmax(u, 0.0), 1.0) * convert_double8(ns);
    const double8 y = fmin(fmax(v, 0.0), 1.0) * convert_double8(ns);
    const long8 a = min(max(convert_long8(floor(x)), (long8)(0)), ns - 1);
    const long8 b = min(max(convert_long8(floor(y)), (long8)(0)), ns - 1 - a);
    const double8 ex = x - convert_double8(a), ey = y - convert_double8(b);
    const long8 up = (ex + ey <= 1.0) | (a + b >= ns - 1);
    const long8 within = select(ns * (ns + 1) / 2 + a * (ns - 1) - a * (a - 1) / 2 + b,
                                a * ns - a * (a - 1) / 2 + b, up);
    *b1 = fmin(fmax(select(ex + ey - 1.0, ex, up), 0.0), 1.0);
    *b2 = fmin(fmax(select(1.0 - ex, ey, up), 0.0), 1.0 - *b1);
    return offset + within;
}

#endif
