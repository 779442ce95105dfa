// PLX_HD marks per-ray and per-sample math that is compiled for both the CPU (g++) and the
// GPU (nvcc). Everything under core/math and core/kernels uses it; see DESIGN.md §3.
#pragma once

#if defined(__CUDACC__)
#define PLX_HD __host__ __device__ inline
#define PLX_HD_LAMBDA __host__ __device__
#else
#define PLX_HD inline
#define PLX_HD_LAMBDA
#endif
