// CPU shell for core/kernels/tv_impl.h (the CUDA twin is cuda/tv_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/tv_impl.h"
