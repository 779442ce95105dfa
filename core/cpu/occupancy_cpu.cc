// CPU shell for core/kernels/occupancy_impl.h (the CUDA twin is cuda/occupancy_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/occupancy_impl.h"
