// Allocation failure as a Status: the large arrays of maps, frames and optimiser state come
// from std::vector-like containers that throw std::bad_alloc when memory (host, or CUDA managed
// memory through the UnifiedVector hooks) runs out. Entry points that serve one request catch
// it here, so the request fails with RESOURCE_EXHAUSTED and the process keeps serving others.
#pragma once

#include <new>
#include <type_traits>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace plx {

// Runs `body` (returning absl::Status or absl::StatusOr<T>); an allocation failure inside it
// becomes RESOURCE_EXHAUSTED "<what>: out of memory".
template <typename Body>
auto CatchAllocationFailure(absl::string_view what, Body&& body) -> decltype(body()) {
  try {
    return std::forward<Body>(body)();
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(absl::StrCat(what, ": out of memory"));
  }
}

}  // namespace plx
