#include "core/kernels/kernel_buffers.h"

#include "absl/strings/str_cat.h"

namespace plx {

std::string ArgumentLabel(const char* group, const char* name) {
  return group == nullptr ? std::string(name) : absl::StrCat(group, ".", name);
}

}  // namespace plx
