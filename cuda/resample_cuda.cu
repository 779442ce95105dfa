// CUDA shell for core/kernels/resample_impl.h (the CPU twin is core/cpu/resample_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/resample_impl.h"
