// CUDA shell for core/kernels/fusion_impl.h (the CPU twin is core/cpu/fusion_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/fusion_impl.h"
