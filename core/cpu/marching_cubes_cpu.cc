// CPU shell for core/kernels/marching_cubes_impl.h (the CUDA twin is cuda/marching_cubes_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/marching_cubes_impl.h"
