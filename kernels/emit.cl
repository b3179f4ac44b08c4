// Photon emission: pick an emitter by power (binary search in the CDF) and sample an origin, a
// direction and an RGB weight. NumPy twin and formulas: kernels/emit.py::emit_reference.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "lanes.cl"

#define EMIT_POINT 0
#define EMIT_SPOT 1
#define EMIT_DIRECTIONAL 2
#define EMIT_AREA 3
#define EMIT_SKY 4
#define EMISSION_STREAM 0xFFFF0000u

inline long8 is_dir_light(const long8 k) { return k == (long8)(EMIT_DIRECTIONAL); }

// Eight photons a work item in explicit vector types, for the reasons given in lanes.cl: every
// lane computes the four kinds of emitter and keeps its own. Lane l of work item g is photon
// min(8 g + l, count - 1); past the end, lanes repeat the last photon and write the same values.
__kernel void emit8(
    const long count, const uint key0, const uint key1, const int n_emitters,
    const double cx, const double cy, const double cz, const double radius, const double epsilon,
    __global const long *photon,
    __global const double *cdf, __global const double *prob, __global const int *kind,
    __global const long *index, __global const double *flux,
    __global const double *light_pos, __global const double *light_dir, __global const double *light_rad,
    __global const double *cos_outer, __global const double *cos_inner,
    __global const float *corners, __global const double *normals,
    __global const long *light_cells, __global const double *cell_size, __global const double *cells,
    __global float *origin_out, __global float *dir_out, __global double *beta_out, __global int *emitter)
{
    const long8 i = min((long8)(8 * (long)get_global_id(0)) + (long8)(0, 1, 2, 3, 4, 5, 6, 7),
                        (long8)(count - 1));
    const long8 ph = G8(long8, photon, i);
    uint8 r0 = convert_uint8(ph & 0xFFFFFFFFL), r1 = convert_uint8(ph >> 32);
    uint8 r2 = (uint8)(EMISSION_STREAM), r3 = (uint8)(0u);
    PHILOX8_10(r0, r1, r2, r3, key0, key1);
    uint8 s0 = convert_uint8(ph & 0xFFFFFFFFL), s1 = convert_uint8(ph >> 32);
    uint8 s2 = (uint8)(EMISSION_STREAM + 1u), s3 = (uint8)(0u);
    PHILOX8_10(s0, s1, s2, s3, key0, key1);
    const double8 w0 = uniform8(r0), u1 = uniform8(r1), u2 = uniform8(r2), u3 = uniform8(r3), u4 = uniform8(s0);

    // First emitter whose CDF exceeds w0 (numpy.searchsorted side="right"), clamped to the last
    long8 lo = (long8)(0), hi = (long8)(n_emitters);
    while (any(lo < hi)) {
        const long8 active = lo < hi;
        const long8 mid = (lo + hi) / 2;
        const long8 go = active & (G8(double8, cdf, min(mid, (long8)(n_emitters - 1))) <= w0);
        lo = select(lo, mid + 1, go);
        hi = select(hi, mid, active & ~go);
    }
    const long8 e = min(lo, (long8)(n_emitters - 1));
    const long8 k = convert_long8(G8(int8, kind, e));
    const long8 src = G8(long8, index, e);
    const long8 is_area = k == (long8)(EMIT_AREA);
    const long8 tri = select((long8)(0), src, is_area);
    const long8 li = select(src, (long8)(0), is_area);

    // Emissive triangle: uniform on it, cosine-weighted about its front normal
    const double8 su = sqrt(u1);
    const double8 b1 = su * (1.0 - u2), b2 = su * u2, b0 = 1.0 - b1 - b2;
    const long8 c9 = 9 * tri;
    const double8 nx = G8(double8, normals, 3 * tri), ny = G8(double8, normals, 3 * tri + 1),
                  nz = G8(double8, normals, 3 * tri + 2);
    double8 adx, ady, adz;
    around8(nx, ny, nz, sqrt(1.0 - u3), 2.0 * M_PI * u4, &adx, &ady, &adz);
    const double8 off = surface_offset8(corners, c9, epsilon);
    const double8 aox = b0 * convert_double8(G8(float8, corners, c9)) + b1 * convert_double8(G8(float8, corners, c9 + 3))
                      + b2 * convert_double8(G8(float8, corners, c9 + 6)) + nx * off;
    const double8 aoy = b0 * convert_double8(G8(float8, corners, c9 + 1)) + b1 * convert_double8(G8(float8, corners, c9 + 4))
                      + b2 * convert_double8(G8(float8, corners, c9 + 7)) + ny * off;
    const double8 aoz = b0 * convert_double8(G8(float8, corners, c9 + 2)) + b1 * convert_double8(G8(float8, corners, c9 + 5))
                      + b2 * convert_double8(G8(float8, corners, c9 + 8)) + nz * off;

    // Punctual lights
    const double8 ax = G8(double8, light_dir, 3 * li), ay = G8(double8, light_dir, 3 * li + 1),
                  az = G8(double8, light_dir, 3 * li + 2);
    const double8 rr = G8(double8, light_rad, 3 * li), rg = G8(double8, light_rad, 3 * li + 1),
                  rb = G8(double8, light_rad, 3 * li + 2);
    const double8 lx = G8(double8, light_pos, 3 * li), ly = G8(double8, light_pos, 3 * li + 1),
                  lz = G8(double8, light_pos, 3 * li + 2);
    double8 pdx, pdy, pdz;  // point: uniform on the sphere
    around8((double8)(0.0), (double8)(0.0), (double8)(1.0), 1.0 - 2.0 * u1, 2.0 * M_PI * u2, &pdx, &pdy, &pdz);
    const double8 co = G8(double8, cos_outer, li), ci = G8(double8, cos_inner, li);
    const double8 cos_t = 1.0 - u1 * (1.0 - co);  // spot: uniform in the outer cone
    double8 sdx, sdy, sdz;
    around8(ax, ay, az, cos_t, 2.0 * M_PI * u2, &sdx, &sdy, &sdz);
    double8 f = fmin(fmax((cos_t - co) / (ci - co), 0.0), 1.0);
    f = f * f;
    const double8 spot_s = f * (2.0 * M_PI * (1.0 - co));
    // directional: a disk of the scene's radius facing the light, upstream of the scene
    const double8 r = radius * sqrt(u1), phi = 2.0 * M_PI * u2;
    double8 tx, ty, tz, sx, sy, sz, sp, cp;
    basis8(ax, ay, az, &tx, &ty, &tz, &sx, &sy, &sz);
    sincos8(phi, &sp, &cp);
    // or a projection map (light_cells n > 0): uniform on its n cells of side h
    const long8 cell_start = G8(long8, light_cells, 2 * li), cell_n = G8(long8, light_cells, 2 * li + 1);
    const double8 h = G8(double8, cell_size, li);
    const long8 mapped = is_dir_light(k) & (cell_n > 0L);
    const double8 n_cells = convert_double8(cell_n);
    const long8 j = select((long8)(0), cell_start + min(convert_long8(u3 * n_cells), cell_n - 1L), mapped);
    const double8 rc = select(r * cp, G8(double8, cells, 2 * j) + u1 * h, mapped);
    const double8 rs = select(r * sp, G8(double8, cells, 2 * j + 1) + u2 * h, mapped);
    const double8 dir_area = select((double8)(M_PI * radius * radius), n_cells * h * h, mapped);
    const double back = radius * 1.05;
    const double8 dox = cx + (tx * rc + sx * rs) - ax * back;
    const double8 doy = cy + (ty * rc + sy * rs) - ay * back;
    const double8 doz = cz + (tz * rc + sz * rs) - az * back;
    // sky half: uniform on the hemisphere about its axis, from a disk facing that direction
    double8 kdx, kdy, kdz;
    around8(ax, ay, az, u1, 2.0 * M_PI * u2, &kdx, &kdy, &kdz);
    const double8 kr = radius * sqrt(u3);
    double8 ktx, kty, ktz, ksx, ksy, ksz, ksp, kcp;
    basis8(kdx, kdy, kdz, &ktx, &kty, &ktz, &ksx, &ksy, &ksz);
    sincos8(2.0 * M_PI * u4, &ksp, &kcp);
    const double8 krc = kr * kcp, krs = kr * ksp;
    const double8 kox = cx + (ktx * krc + ksx * krs) - kdx * back;
    const double8 koy = cy + (kty * krc + ksy * krs) - kdy * back;
    const double8 koz = cz + (ktz * krc + ksz * krs) - kdz * back;
    const long8 is_sky = k == (long8)(EMIT_SKY);
    const double8 scale = select(select(select(select(dir_area, spot_s, k == (long8)(EMIT_SPOT)),
                                               (double8)(4.0 * M_PI), k == (long8)(EMIT_POINT)),
                                        (double8)(2.0 * M_PI * (M_PI * radius * radius)), is_sky),
                                 (double8)(0.0), is_area);

    const long8 is_point = k == (long8)(EMIT_POINT), is_spot = k == (long8)(EMIT_SPOT);
    const long8 is_dir = k == (long8)(EMIT_DIRECTIONAL);
    const double8 ox = select(select(select(lx, dox, is_dir), kox, is_sky), aox, is_area);
    const double8 oy = select(select(select(ly, doy, is_dir), koy, is_sky), aoy, is_area);
    const double8 oz = select(select(select(lz, doz, is_dir), koz, is_sky), aoz, is_area);
    const double8 dx = select(select(select(select(ax, sdx, is_spot), pdx, is_point), kdx, is_sky), adx, is_area);
    const double8 dy = select(select(select(select(ay, sdy, is_spot), pdy, is_point), kdy, is_sky), ady, is_area);
    const double8 dz = select(select(select(select(az, sdz, is_spot), pdz, is_point), kdz, is_sky), adz, is_area);
    const double8 wr = select(rr * scale, G8(double8, flux, 3 * e), is_area);
    const double8 wg = select(rg * scale, G8(double8, flux, 3 * e + 1), is_area);
    const double8 wb = select(rb * scale, G8(double8, flux, 3 * e + 2), is_area);
    const double8 p = G8(double8, prob, e);
    S8(origin_out, 3 * i, convert_float8(ox));
    S8(origin_out, 3 * i + 1, convert_float8(oy));
    S8(origin_out, 3 * i + 2, convert_float8(oz));
    S8(dir_out, 3 * i, convert_float8(dx));
    S8(dir_out, 3 * i + 1, convert_float8(dy));
    S8(dir_out, 3 * i + 2, convert_float8(dz));
    S8(beta_out, 3 * i, wr / p);
    S8(beta_out, 3 * i + 1, wg / p);
    S8(beta_out, 3 * i + 2, wb / p);
    S8(emitter, i, convert_int8(e));
}
