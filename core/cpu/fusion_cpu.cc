// CPU shell for core/kernels/fusion_impl.h (the CUDA twin is cuda/fusion_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/fusion_impl.h"
