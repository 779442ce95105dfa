// CPU shell for core/kernels/optimizer_impl.h (the CUDA twin is cuda/optimizer_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/optimizer_impl.h"
