// Backend implementation on CPU threads: forwards every kernel to its plx::cpu driver.
#include "core/cpu/cpu_backend.h"

#include <memory>
#include <variant>

#include "core/cpu/kernels_cpu.h"

namespace plx {
namespace {

class CpuBackend final : public Backend {
 public:
  CpuBackend(int num_threads, int nice) {
    if (num_threads > 0 || nice > 0) {
      own_pool_ = std::make_unique<cpu::ThreadPool>(num_threads, nice);
      ctx_.pool = own_pool_.get();
    }
  }

  std::string name() const override { return "cpu"; }
  int parallelism() const override { return ctx_.pool->num_threads(); }

 private:
  absl::Status Launch(const KernelArgs& call) override {
    return std::visit(
        [this](const auto& args) { return CallDriver([&] { return cpu::Run(ctx_, args); }); },
        call);
  }

  std::unique_ptr<cpu::ThreadPool> own_pool_;
  cpu::ExecContext ctx_;
};

}  // namespace

std::unique_ptr<Backend> MakeCpuBackend(int num_threads, int nice) {
  return std::make_unique<CpuBackend>(num_threads, nice);
}

}  // namespace plx
