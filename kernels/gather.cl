// Illumination reconstruction from photon records (§4, §5.2.4): per-element sums of
// vertex-weighted energies, window sums over frames, element -> vertex distribution.
//
// Deterministic by construction: every output is written by one work item that adds its inputs
// in a fixed order (no atomics; shared/notes/ecosystem.md §3). Accumulation is double.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define SLOTS 12          // 3 corners x (R, G, B, Q); Q = sum of b_k^2 Y^2 for the variance
#define BARY_SCALE 65535.0
#define DIRECT_BIT 0x80000000u
#define PARITY_BIT 0x40000000u

// Sums of segment s (a (frame, element) pair; records [offsets[s], offsets[s+1]), element-sorted):
// out[s, p, k, c] = sum over its records of parity p of b_k * energy_c, and Q = b_k^2 * Y^2
// (dept.md §1.2-1.3). `kinds`: bit 0 takes indirect records, bit 1 direct ones.
__kernel void element_sums(__global const uint *key, __global const ushort *b1,
                           __global const ushort *b2, __global const float *energy,
                           __global const long *offsets, const long n_segments,
                           const uint kinds, const int n_parity,
                           __global double *out)  // (n_segments, n_parity, 12)
{
    const long s = get_global_id(0);
    if (s >= n_segments) return;
    double acc[2 * SLOTS];
    for (int i = 0; i < 2 * SLOTS; ++i) acc[i] = 0.0;
    const long end = offsets[s + 1];
    for (long r = offsets[s]; r < end; ++r) {
        const uint k = key[r];
        if (!(kinds & ((k & DIRECT_BIT) ? 2u : 1u))) continue;
        const int p = (n_parity == 2 && (k & PARITY_BIT)) ? SLOTS : 0;
        const double w1 = (double)b1[r] / BARY_SCALE;
        const double w2 = (double)b2[r] / BARY_SCALE;
        const double w[3] = {1.0 - w1 - w2, w1, w2};
        const double red = (double)energy[3 * r], green = (double)energy[3 * r + 1],
                     blue = (double)energy[3 * r + 2];
        const double y = 0.2126 * red + 0.7152 * green + 0.0722 * blue;  // Rec. 709 luminance
        const double y2 = y * y;
        for (int c = 0; c < 3; ++c) {
            double *a = acc + p + 4 * c;
            a[0] += w[c] * red;
            a[1] += w[c] * green;
            a[2] += w[c] * blue;
            a[3] += (w[c] * w[c]) * y2;
        }
    }
    __global double *o = out + s * n_parity * SLOTS;
    for (int i = 0; i < n_parity * SLOTS; ++i) o[i] = acc[i];
}

// In-place prefix sums over frames: rows 1..n_rows of `table` (row 0 all zero) become
// row[j] = row[j-1] + row[j]; one work item per column, rows in order.
__kernel void prefix_frames(__global double *table, const int n_rows, const long width)
{
    const long i = get_global_id(0);
    if (i >= width) return;
    double run = 0.0;
    for (int j = 1; j <= n_rows; ++j) {
        run += table[j * width + i];
        table[j * width + i] = run;
    }
}

// One output frame's element-corner flux over each element's window [f - back, f + fwd]:
// U = window sum / sum of N_g over the window (/ its square for Q). `rows` in the frame range
// of the sums table: output frame f is row `row`. prefix != 0: table holds prefix sums (row 0 =
// 0, row j+1 = sum of frames 0..j) and a window sum is a difference of two rows; prefix == 0:
// table holds per-frame sums (row j = frame j) added in frame order.
__kernel void window_flux(__global const double *table, __global const double *cum_n,
                          __global const uchar *back, __global const uchar *fwd,
                          const long window_base, const int row, const int n_elements,
                          const int n_parity,
                          const int prefix, __global double *flux)  // (E, n_parity, 12)
{
    const int e = get_global_id(0);
    if (e >= n_elements) return;
    const int lo = row - back[window_base + e], hi = row + fwd[window_base + e] + 1;  // frames [lo, hi)
    const int width = n_parity * SLOTS;
    const long stride = (long)n_elements * width;
    const double n_sum = (cum_n[hi] - cum_n[lo]) / (double)n_parity;  // photons per half
    __global double *o = flux + (long)e * width;
    for (int i = 0; i < width; ++i) {
        double total;
        if (prefix) {
            total = table[hi * stride + (long)e * width + i] - table[lo * stride + (long)e * width + i];
        } else {
            total = 0.0;
            for (int g = lo; g < hi; ++g) total += table[g * stride + (long)e * width + i];
        }
        o[i] = (i % 4 == 3) ? total / (n_sum * n_sum) : total / n_sum;
    }
}

// Element corners -> vertices (Gouraud hat basis, dept.md §1.2): vertex v adds the flux of the
// element corners in slots[voffsets[v] .. voffsets[v+1]) (element * 3 + corner, ascending).
__kernel void vertex_flux(__global const double *flux, __global const long *voffsets,
                          __global const int *slots, const int n_vertices, const int n_parity,
                          __global double *out)  // (n_parity, V, 4)
{
    const int v = get_global_id(0);
    if (v >= n_vertices) return;
    for (int p = 0; p < n_parity; ++p) {
        double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
        for (long j = voffsets[v]; j < voffsets[v + 1]; ++j) {
            const int ek = slots[j];
            const int e = ek / 3, k = ek - 3 * (ek / 3);
            __global const double *u = flux + ((long)e * n_parity + p) * SLOTS + 4 * k;
            a0 += u[0]; a1 += u[1]; a2 += u[2]; a3 += u[3];
        }
        __global double *o = out + ((long)p * n_vertices + v) * 4;
        o[0] = a0; o[1] = a1; o[2] = a2; o[3] = a3;
    }
}
