// CUDA shell for core/kernels/render_impl.h (the CPU twin is core/cpu/render_cpu.cc).
#define PLX_BACKEND_NS cuda
#include "cuda/kernels_cuda.h"
#include "core/kernels/render_impl.h"
