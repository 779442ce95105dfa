// CPU shell for core/kernels/mapping_impl.h (the CUDA twin is cuda/mapping_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/mapping_impl.h"
