// Illumination reconstruction from photon records (§4, §5.2.4): per-element sums of
// vertex-weighted energies, window sums over frames, element -> vertex distribution.
//
// Deterministic by construction: every output is written by one work item that adds its inputs
// in a fixed order (no atomics; docs/15-opencl.md §2). Accumulation is double.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define SLOTS 12          // 3 corners x (R, G, B, Q); Q = sum of b_k^2 Y^2 for the variance
// BARY_SCALE, DIRECT_BIT, PARITY_BIT (kernels/record_layout.py) and LUMA_R/G/B (kernels/colour.py)
// are build options (kernels/context.py)

// Adds the records [begin, end) of the kinds asked for (and, with n_parity = 2, of photon parity
// `parity` only) to acc: acc[4k + c] += b_k * energy_c, acc[4k + 3] += b_k^2 * Y^2.
inline void add_records(__global const uint *key, __global const ushort *b1,
                        __global const ushort *b2, __global const float *energy, const long begin,
                        const long end, const uint kinds, const int n_parity, const uint parity,
                        double acc[SLOTS])
{
    for (long r = begin; r < end; ++r) {
        const uint k = key[r];
        if (!(kinds & ((k & DIRECT_BIT) ? 2u : 1u))) continue;
        if (n_parity == 2 && ((k & PARITY_BIT) ? 1u : 0u) != parity) continue;
        const double w1 = (double)b1[r] / BARY_SCALE;
        const double w2 = (double)b2[r] / BARY_SCALE;
        const double w0 = 1.0 - w1 - w2;
        const double red = (double)energy[3 * r], green = (double)energy[3 * r + 1],
                     blue = (double)energy[3 * r + 2];
        const double y = LUMA_R * red + LUMA_G * green + LUMA_B * blue;  // Rec. 709 luminance
        const double y2 = y * y;
        acc[0] += w0 * red; acc[1] += w0 * green; acc[2] += w0 * blue; acc[3] += (w0 * w0) * y2;
        acc[4] += w1 * red; acc[5] += w1 * green; acc[6] += w1 * blue; acc[7] += (w1 * w1) * y2;
        acc[8] += w2 * red; acc[9] += w2 * green; acc[10] += w2 * blue; acc[11] += (w2 * w2) * y2;
    }
}

// Sums of segment s (a (frame, element) pair; records [offsets[s], offsets[s+1]), element-sorted)
// for parity p (work item (s, p)): out[(s * n_parity + p) * 12 + 4k + c] = sum over the
// records of b_k * energy_c, and (c = 3) Q = sum b_k^2 * Y^2 (docs/05-estimators.md §1.2-1.3). With n_parity = 1
// every record counts. `kinds`: bit 0 takes indirect records, bit 1 direct ones.
__kernel void element_sums(__global const uint *key, __global const ushort *b1,
                           __global const ushort *b2, __global const float *energy,
                           __global const uint *offsets, const long n_segments,
                           const uint kinds, const int n_parity,
                           __global double *out)
{
    const long gid = get_global_id(0);
    if (gid >= n_segments * n_parity) return;
    const long s = gid / n_parity;
    const uint parity = (uint)(gid - s * n_parity);
    double acc[SLOTS];
    for (int c = 0; c < SLOTS; ++c) acc[c] = 0.0;
    add_records(key, b1, b2, energy, (long)offsets[s], (long)offsets[s + 1], kinds, n_parity, parity, acc);
    __global double *o = out + gid * SLOTS;
    for (int c = 0; c < SLOTS; ++c) o[c] = acc[c];
}

// Row 0 of element e's part of the element-major prefix table (E, n_frames + 1, n_parity x SLOTS)
// for work item gid = e * n_parity + p, with p's columns: rows follow at a stride of `width`.
inline __global double *prefix_rows(__global double *table, const long gid, const int n_frames,
                                    const int n_parity, long *e, uint *parity, long *width) {
    *e = gid / n_parity;
    *parity = (uint)(gid - *e * n_parity);
    *width = (long)n_parity * SLOTS;
    return table + *e * (n_frames + 1) * *width + *parity * SLOTS;
}

// The element-major prefix table (E, J + 1, n_parity, 12) over frames 0..J-1 from per-frame
// element sums already made (element_sums of frame j, laid out (E, n_parity, 12)), one launch a
// frame: row j + 1 = row j + sums of frame j, row 0 zeroed with frame 0. An element's rows are
// contiguous, so this kernel writes and vertex_window_flux reads memory in order.
__kernel void frame_sums_prefix_step(__global const double *sums, const int j, const int n_frames,
                                     const int n_elements, const int n_parity, __global double *table)
{
    const long gid = get_global_id(0);
    if (gid >= (long)n_elements * n_parity) return;
    long e, width;
    uint parity;
    __global double *t = prefix_rows(table, gid, n_frames, n_parity, &e, &parity, &width);
    if (j == 0) {
        for (int c = 0; c < SLOTS; ++c) t[c] = 0.0;
    }
    __global const double *acc = sums + gid * SLOTS;
    __global const double *prev = t + (long)j * width;
    __global double *o = t + (long)(j + 1) * width;
    for (int c = 0; c < SLOTS; ++c) o[c] = prev[c] + acc[c];
}

// The value at x = 0 of the window's least-squares line (docs/05-estimators.md §1.6), its slope shrunk by
// the positive-part James-Stein factor 1 - var(slope) / slope^2 of its photon noise (luminance): `t`
// the window sum (R, G, B, Q), n, x1, x2 its photons and their first two moments of x = g - row, s1
// the sums' first moment, w1, w2 Q's first two; u gets (R, G, B) per photon emitted and the variance.
inline void fit_at_frame(const double t[4], const double n, const double x1, const double x2, const double s1[3],
                         const double w1, const double w2, double u[4])
{
    const double xb = x1 / n, sxx = x2 - x1 * xb;
    double lam = 0.0, beta[3] = {0.0, 0.0, 0.0}, var_b = 0.0;
    if (sxx > 1e-9 * n) {
        for (int c = 0; c < 3; ++c) beta[c] = (s1[c] - xb * t[c]) / sxx;
        var_b = fmax(w2 - 2.0 * xb * w1 + xb * xb * t[3], 0.0) / (sxx * sxx);
        const double by = LUMA_R * beta[0] + LUMA_G * beta[1] + LUMA_B * beta[2];
        if (by * by > var_b) lam = 1.0 - var_b / (by * by);
    }
    for (int c = 0; c < 3; ++c) u[c] = fmax(t[c] / n - xb * lam * beta[c], 0.0);
    u[3] = t[3] / (n * n) + xb * xb * lam * lam * var_b;
}

// One walk over a window's frames [lo, hi), read as differences of consecutive prefix rows (each row
// once), x = g - row. Accumulates the sums' first moment s1 and Q's first two w1, w2.
inline void window_moments(__global const double *te, const long width, const int lo, const int hi,
                           const int row, double s1[3], double *w1, double *w2)
{
    double prev[4];
    __global const double *a0 = te + (long)lo * width;
    for (int c = 0; c < 4; ++c) prev[c] = a0[c];
    for (int g = lo; g < hi; ++g) {
        const double x = (double)(g - row);
        __global const double *b = te + (long)(g + 1) * width;
        double d[4];
        for (int c = 0; c < 4; ++c) { d[c] = b[c] - prev[c]; prev[c] = b[c]; }
        for (int c = 0; c < 3; ++c) s1[c] += x * d[c];
        *w1 += x * d[3]; *w2 += x * x * d[3];
    }
}

// The linear-window estimate of one element corner: fit_at_frame of the line, weighted by photons
// emitted, through the window's per-frame sums. `t` is the window sum, n, x1, x2 its photons' moments
// (all from prefix sums); the walk adds only the sums' moments.
inline void linear_window(__global const double *te, const long width, const int lo, const int hi,
                          const int row, const double n, const double x1, const double x2,
                          const double t[4], double u[4])
{
    double s1[3] = {0.0, 0.0, 0.0}, w1 = 0.0, w2 = 0.0;
    window_moments(te, width, lo, hi, row, s1, &w1, &w2);
    fit_at_frame(t, n, x1, x2, s1, w1, w2, u);
}

// Vertex flux of every output frame i (work item v; frames in order, so an element's rows are
// read while in cache): vertex v adds, over the element corners in slots[voffsets[v] ..
// voffsets[v+1]) (element * 3 + corner, ascending), the corner's window sum over its element's
// window [f - back, f + fwd] divided by the photons emitted in the window, U = sum / sum_g N_g
// (Q: / (sum_g N_g)^2), with N_g halved per parity. Output frame i is frame rows[i] of the
// element-major prefix table (E, n_table_rows, n_parity, 12) of frame_sums_prefix_step (row 0 = 0,
// row j+1 = sum of frames 0..j): a window sum is the difference of two rows. With `linear`, a corner
// gives its linear-window estimate (linear_window) instead of the pooled mean.
__kernel void vertex_window_flux(__global const double *table, __global const double *cum_n,
                                 __global const double *cum_gn, __global const double *cum_ggn,
                                 __global const uchar *back, __global const uchar *fwd, // (E, n_out)
                                 __global const int *rows, __global const long *voffsets,
                                 __global const int *slots, const int n_vertices,
                                 const int n_elements, const int n_parity, const int n_table_rows,
                                 const int n_out, const int linear,
                                 __global double *out)  // (V, n_out, n_parity, 4)
{
    const int v = get_global_id(0);
    if (v >= n_vertices) return;
    const long width = (long)n_parity * SLOTS;
    const long j0 = voffsets[v], j1 = voffsets[v + 1];
    for (int i = 0; i < n_out; ++i) {
        const int row = rows[i];
        for (int p = 0; p < n_parity; ++p) {
            double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
            for (long j = j0; j < j1; ++j) {
                const int ek = slots[j];
                const int e = ek / 3, k = ek - 3 * (ek / 3);
                const long w = (long)e * n_out + i;
                const int lo = row - back[w], hi = row + fwd[w] + 1;  // frames [lo, hi)
                const double np = cum_n[hi] - cum_n[lo];  // photons emitted in the window
                const double inv_n = (double)n_parity / np;  // 1 / photons of one parity
                __global const double *te = table + (long)e * n_table_rows * width + p * SLOTS + 4 * k;
                double t[4];
                for (int c = 0; c < 4; ++c) t[c] = te[hi * width + c] - te[lo * width + c];
                // Linear windows: the photons' moments of x = g - row from prefix sums (exact: integer
                // photon counts); a window centred on the frame (x1 = 0) is its pooled mean, so only
                // the off-centre ones loop over their frames
                const double g1 = linear ? cum_gn[hi] - cum_gn[lo] : 0.0;
                const double x1 = linear ? (g1 - row * np) / n_parity : 0.0;
                if (fabs(x1) > 1e-12 * np) {
                    const double g2 = cum_ggn[hi] - cum_ggn[lo];
                    const double x2 = (g2 - 2.0 * row * g1 + (double)row * row * np) / n_parity;
                    double u[4];
                    linear_window(te, width, lo, hi, row, np / n_parity, x1, x2, t, u);
                    a0 += u[0]; a1 += u[1]; a2 += u[2]; a3 += u[3];
                } else {
                    a0 += t[0] * inv_n; a1 += t[1] * inv_n; a2 += t[2] * inv_n;
                    a3 += t[3] * (inv_n * inv_n);
                }
            }
            __global double *o = out + (((long)v * n_out + i) * n_parity + p) * 4;
            o[0] = a0; o[1] = a1; o[2] = a2; o[3] = a3;
        }
    }
}
