// Where camera and reflection hits land on the element mesh, and the indirect irradiance there:
// the element (ElementMesh.locate's arithmetic) and the barycentric blend of its three vertex
// values, E0 + b1 (E1 - E0) + b2 (E2 - E0) (pipeline/frames/shading_tables.py). Eight hits a work item, as in
// scatter.cl. NumPy twin: kernels/surface.py::lookup_reference.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF  // no fused multiply-add: the NumPy twin rounds every product
#include "lanes.cl"

__kernel void lookup8(const long count, const int blend,
                      __global const int *tri, __global const float *hit_u, __global const float *hit_v,
                      __global const int *tri_n, __global const long *tri_offset,
                      __global const float *element_irradiance,  // (E, 3, 3): E0, E1 - E0, E2 - E0
                      __global long *cell_out, __global float *indirect_out)
{
    const long8 i = min((long8)(8 * (long)get_global_id(0)) + (long8)(0, 1, 2, 3, 4, 5, 6, 7),
                        (long8)(count - 1));
    const long8 t = convert_long8(G8(int8, tri, i));
    const double8 u = convert_double8(G8(float8, hit_u, i)), v = convert_double8(G8(float8, hit_v, i));
    double8 b1, b2;
    const long8 e = locate8(convert_long8(G8(int8, tri_n, t)), G8(long8, tri_offset, t), u, v, &b1, &b2);
    S8(cell_out, i, e);
    if (blend) {
        const float8 f1 = convert_float8(b1), f2 = convert_float8(b2);
        const long8 base = 9 * e;
        for (int c = 0; c < 3; ++c) {
            const float8 e0 = G8(float8, element_irradiance, base + c);
            const float8 d1 = G8(float8, element_irradiance, base + 3 + c);
            const float8 d2 = G8(float8, element_irradiance, base + 6 + c);
            S8(indirect_out, 3 * i + c, e0 + f1 * d1 + f2 * d2);
        }
    }
}
