// CUDA shell for core/kernels/tv_impl.h (the CPU twin is core/cpu/tv_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/tv_impl.h"
