// Adaptive object-space filter (§5.2.5; Volevich et al. 2000, Myszkowski 1997): see
// kernels/filter.py for the estimator. One work item per (parity, vertex); rings of neighbours
// are added in CSR order, double, no fused multiply-add, so the NumPy twin agrees exactly.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

inline double luma(const double r, const double g, const double b)
{
    return LUMA_R * r + LUMA_G * g + LUMA_B * b;  // Rec. 709, build options from kernels/colour.py
}

// flux (V, L, 4), vertex-major as kernels/gather.py makes it: RGB S and variance term Q per
// vertex for L maps (frames x parities); areas A_v, (V,) for all maps (areas_stride 0) or (L, V)
// (areas_stride V). Work item (v, p) with p fastest: neighbouring work items read neighbouring
// memory.
// Neighbours of v: nbr[noff[v] .. noff[v+1]) ordered by ring, ring r (1..max_rings) starting at
// ring_start[v * (max_rings + 1) + r - 1] and ending at ring_start[v * (max_rings + 1) + r].
// Out: irradiance (V, L, 3) and the number of rings taken (V, L).
__kernel void adaptive_filter(__global const double *flux, __global const double *areas,
                              __global const int *nbr, __global const long *ring_start,
                              const long areas_stride,
                              const int n_vertices, const int n_parity, const int max_rings,
                              const double tau2, const double z2,
                              __global double *out, __global uchar *rings)
{
    const long gid = get_global_id(0);
    if (gid >= (long)n_parity * n_vertices) return;
    const int v = (int)(gid / n_parity);
    const int p = (int)(gid - (long)v * n_parity);
    const long step = (long)n_parity * 4;  // from one vertex to the next
    __global const double *fp = flux + p * 4;
    areas += p * areas_stride;
    double s0 = fp[step * v], s1 = fp[step * v + 1], s2 = fp[step * v + 2], q = fp[step * v + 3];
    double a = areas[v];
    double y = luma(s0, s1, s2);
    int taken = 0;
    for (int r = 1; r <= max_rings; ++r) {
        if (y > 0.0 && q <= tau2 * (y * y)) break;  // relative std sqrt(Q)/Y within tau
        const long lo = ring_start[(long)v * (max_rings + 1) + r - 1];
        const long hi = ring_start[(long)v * (max_rings + 1) + r];
        if (lo == hi) break;  // no more neighbours on this surface
        double t0 = 0.0, t1 = 0.0, t2 = 0.0, tq = 0.0, ta = 0.0;
        for (long j = lo; j < hi; ++j) {
            const int u = nbr[j];
            t0 += fp[step * u]; t1 += fp[step * u + 1]; t2 += fp[step * u + 2]; tq += fp[step * u + 3];
            ta += areas[u];
        }
        // Bias test (docs/05-estimators.md §1.5 step 4): the ring's estimate must agree with the inner one
        // within z standard deviations; an inner region without photons always grows.
        if (y > 0.0 && a > 0.0 && ta > 0.0) {
            const double e_in = y / a, e_ring = luma(t0, t1, t2) / ta;
            const double var = q / (a * a) + tq / (ta * ta);
            const double d = e_ring - e_in;
            if (d * d > z2 * var) break;
        }
        s0 += t0; s1 += t1; s2 += t2; q += tq; a += ta;
        y = luma(s0, s1, s2);
        taken = r;
    }
    __global double *o = out + gid * 3;
    if (a > 0.0) {
        o[0] = s0 / a; o[1] = s1 / a; o[2] = s2 / a;
    } else {
        o[0] = 0.0; o[1] = 0.0; o[2] = 0.0;
    }
    rings[gid] = (uchar)taken;
}
