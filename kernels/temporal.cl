// Temporal photon collection windows, Condition (1) of §5.1 (paper: Myszkowski et al. 2001).
//
// Every quantity is double and the pragma below forbids fused multiply-adds, so each result is
// the correctly rounded value of the same sequence of operations as kernels/temporal.py's NumPy
// twin (windows_reference), and the windows agree exactly.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

// Smoothed hit rate per emitted photon, over `smoothing` frames centred on g, clipped to the
// animation's ends and to the element's lighting steps: R[g, e] = (sum_j counts[j, e] / N[j]) / n_g,
// j ascending (§5.1: "the mean number of photons ... for three subsequent frames"), and Q[g, e], the
// mean of 1/N_j over the same frames. cuts[t, e] != 0: the element's lighting steps between frames
// t and t + 1 (pipeline/collection/regional_steps.py); a mean never mixes the two sides.
__kernel void smooth_rates(__global const uint *counts,   // (F, E)
                           __global const double *n_emitted, // (F,) N_frame of every frame
                           __global const uchar *cuts,     // (F, E), row F - 1 unused
                           const int n_frames, const int n_elements, const int half_s,
                           __global double *rate,          // (F, E)
                           __global double *q)             // (F, E)
{
    const long gid = get_global_id(0);
    if (gid >= (long)n_frames * n_elements) return;
    const int g = (int)(gid / n_elements);
    const int e = (int)(gid - (long)g * n_elements);
    int lo = g, hi = g;
    while (lo > max(0, g - half_s) && !cuts[(long)(lo - 1) * n_elements + e])
        --lo;
    while (hi < min(n_frames - 1, g + half_s) && !cuts[(long)hi * n_elements + e])
        ++hi;
    double sum = 0.0, inv = 0.0;
    for (int j = lo; j <= hi; ++j) {
        sum += (double)counts[(long)j * n_elements + e] / n_emitted[j];
        inv += 1.0 / n_emitted[j];
    }
    rate[gid] = sum / (double)(hi - lo + 1);
    q[gid] = inv / (double)(hi - lo + 1);
}

// Condition (1) at candidate frame g for the element whose mean mu was taken at frame f:
// mu - k sigma <= x <= mu + k sigma, i.e. (x - mu)^2 <= k^2 sigma^2 (no square root), counts on
// frame f's photon budget N_f. sigma^2 = mu * N_f * Q[g, e], the mean of 1/N_j over g's smoothing
// frames (so sigma = sqrt(mu) when every frame shoots the same N); sigma = 1 where mu = 0 (§5.1).
inline bool condition1(const double mu, const double n_f, const double rate_g, const double q_g,
                       const double k2)
{
    const double d = n_f * rate_g - mu;
    const double var = mu > 0.0 ? mu * (n_f * q_g) : 1.0;
    return d * d <= k2 * var;
}

// Window [f - back, f + fwd] of every (frame f in [f0, f0 + n_out), element e).
// adaptive != 0: walk backward and forward independently while Condition (1) holds, at most
// F_max/2 frames each way and to the animation's ends; then at least min_extent = half_lo +
// half_hi + 1 frames: at least half_lo back and half_hi forward (clipped likewise).
// adaptive == 0: always +-F_max/2 (§6, Fig. 3b).
__kernel void windows(__global const double *rate,      // (F, E) from smooth_rates
                      __global const double *n_emitted, // (F,)
                      __global const double *q,         // (F, E) mean 1/N over smoothing frames
                      const int n_frames, const int n_elements, const int f0, const int n_out,
                      const int half_fmax, const int half_lo, const int half_hi,
                      const double k2, const int adaptive,
                      __global uchar *back, __global uchar *fwd) // (n_out, E)
{
    const long gid = get_global_id(0);
    if (gid >= (long)n_out * n_elements) return;
    const int i = (int)(gid / n_elements);
    const int e = (int)(gid - (long)i * n_elements);
    const int f = f0 + i;
    const int max_back = min(half_fmax, f);
    const int max_fwd = min(half_fmax, n_frames - 1 - f);
    int b = max_back, w = max_fwd;
    if (adaptive) {
        const double n_f = n_emitted[f];
        const double mu = n_f * rate[(long)f * n_elements + e];
        b = 0;
        while (b < max_back
               && condition1(mu, n_f, rate[(long)(f - b - 1) * n_elements + e],
                             q[(long)(f - b - 1) * n_elements + e], k2))
            ++b;
        w = 0;
        while (w < max_fwd
               && condition1(mu, n_f, rate[(long)(f + w + 1) * n_elements + e],
                             q[(long)(f + w + 1) * n_elements + e], k2))
            ++w;
        b = max(b, min(half_lo, max_back));
        w = max(w, min(half_hi, max_fwd));
    }
    back[gid] = (uchar)b;
    fwd[gid] = (uchar)w;
}
