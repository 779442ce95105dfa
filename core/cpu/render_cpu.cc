// CPU shell for core/kernels/render_impl.h (the CUDA twin is cuda/render_cuda.cu).
#define PLX_BACKEND_NS cpu
#include "core/cpu/kernels_cpu.h"
#include "core/kernels/render_impl.h"
