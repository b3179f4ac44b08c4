// Directions about an axis, shared by the emission and bounce kernels. Twin: kernels/sampling.py.
#ifndef PHOTONLOOM_SAMPLING_CL
#define PHOTONLOOM_SAMPLING_CL
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

// Orthonormal tangents (t, s) of the unit axis z: Duff et al., "Building an orthonormal basis,
// revisited", JCGT 6(1), 2017.
inline void orthonormal_basis(double zx, double zy, double zz, double *tx, double *ty, double *tz,
                              double *sx, double *sy, double *sz) {
    const double sgn = zz >= 0.0 ? 1.0 : -1.0;
    const double ia = -1.0 / (sgn + zz);
    const double ib = zx * zy * ia;
    *tx = 1.0 + sgn * zx * zx * ia; *ty = sgn * ib; *tz = -sgn * zx;
    *sx = ib; *sy = sgn + zy * zy * ia; *sz = -zy;
}

// The direction at polar angle acos(cos_t) and azimuth phi about the unit axis z.
inline void around(double zx, double zy, double zz, double cos_t, double phi,
                   double *ox, double *oy, double *oz) {
    double tx, ty, tz, sx, sy, sz;
    orthonormal_basis(zx, zy, zz, &tx, &ty, &tz, &sx, &sy, &sz);
    const double sin_t = sqrt(fmin(fmax(1.0 - cos_t * cos_t, 0.0), 1.0));
    const double cp = cos(phi), sp = sin(phi);
    *ox = tx * (sin_t * cp) + sx * (sin_t * sp) + zx * cos_t;
    *oy = ty * (sin_t * cp) + sy * (sin_t * sp) + zy * cos_t;
    *oz = tz * (sin_t * cp) + sz * (sin_t * sp) + zz * cos_t;
}

#endif
