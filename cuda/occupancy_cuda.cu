// CUDA shell for core/kernels/occupancy_impl.h (the CPU twin is core/cpu/occupancy_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/occupancy_impl.h"
