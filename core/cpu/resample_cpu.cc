// CPU shell for core/kernels/resample_impl.h (the CUDA twin is cuda/resample_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/resample_impl.h"
