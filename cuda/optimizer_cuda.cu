// CUDA shell for core/kernels/optimizer_impl.h (the CPU twin is core/cpu/optimizer_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/optimizer_impl.h"
