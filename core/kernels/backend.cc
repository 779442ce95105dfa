// The checking half of Backend: every kernel's arguments checked against what its argument
// struct lists (core/kernels/kernel_args.h), and allocation failures turned into a Status,
// before the backend's own Launch.
#include "core/kernels/backend.h"

#include <string>
#include <variant>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"

namespace plx {
namespace {

const char* AccessWord(BufferAccess access) {
  switch (access) {
    case BufferAccess::kRead: return "input";
    case BufferAccess::kWrite: return "output";
    case BufferAccess::kReadWrite: return "in/out";
  }
  return "";
}

// Sizes first (an array's size is computed from them), then the arrays: the first failure.
template <typename Args>
absl::Status CheckListedArguments(const Args& args) {
  absl::Status status;
  auto fail = [&](const auto&... message) {
    status.Update(absl::InvalidArgumentError(absl::StrCat(Args::kName, ": ", message...)));
  };
  ForEachCount(args, [&](const KernelCount& c) {
    if (!status.ok() || c.value >= 0) return;
    fail("`", ArgumentLabel(c.group, c.name), "` must not be negative (got ", c.value, ")");
  });
  ForEachBuffer(args, [&](const KernelBuffer& b) {
    if (!status.ok()) return;
    // Built only for a message: the checks run before every kernel call.
    auto label = [&] {
      return absl::StrCat(AccessWord(b.access), " `", ArgumentLabel(b.group, b.name), "`");
    };
    if (b.sized && b.count < 0) {
      fail(label(), " has a negative size (", b.count, ")");
    } else if (b.required && b.data == nullptr) {
      fail(label(), " is null");
    }
  });
  return status;
}

template <typename Args>
absl::Status CheckArguments(const Args& args) {
  if (absl::Status listed = CheckListedArguments(args); !listed.ok()) return listed;
  if constexpr (requires { args.Validate(); }) {
    if (absl::Status valid = args.Validate(); !valid.ok()) {
      return absl::Status(valid.code(), absl::StrCat(Args::kName, ": ", valid.message()));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status Backend::Run(const KernelArgs& call) {
  return std::visit(
      [&](const auto& args) -> absl::Status {
        using Args = std::decay_t<decltype(args)>;
        if (absl::Status checked = CheckArguments(args); !checked.ok()) return checked;
        if constexpr (requires { args.Empty(); }) {
          if (args.Empty()) return absl::OkStatus();
        }
        return CatchAllocationFailure(Args::kName, [&] { return Launch(call); });
      },
      call);
}

}  // namespace plx
