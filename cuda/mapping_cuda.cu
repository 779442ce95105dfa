// CUDA shell for core/kernels/mapping_impl.h (the CPU twin is core/cpu/mapping_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/mapping_impl.h"
