// CUDA shell for core/kernels/marching_cubes_impl.h (the CPU twin:
// core/cpu/marching_cubes_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/marching_cubes_impl.h"
