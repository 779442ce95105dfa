// CUDA shell for core/kernels/tracking_impl.h (the CPU twin is core/cpu/tracking_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/tracking_impl.h"
