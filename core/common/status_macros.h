// Early-return helpers for absl::Status / absl::StatusOr (abseil does not publish these).
#pragma once

#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#define PLX_STATUS_CONCAT_INNER(a, b) a##b
#define PLX_STATUS_CONCAT(a, b) PLX_STATUS_CONCAT_INNER(a, b)

// Returns the status from the enclosing function when `expr` is not OK.
#define PLX_RETURN_IF_ERROR(expr)                          \
  do {                                                     \
    if (absl::Status plx_status_ = (expr); !plx_status_.ok()) \
      return plx_status_;                                  \
  } while (false)

// `PLX_ASSIGN_OR_RETURN(auto x, Foo());` declares x from an OK StatusOr, returns the error
// otherwise.
#define PLX_ASSIGN_OR_RETURN(lhs, expr) \
  PLX_ASSIGN_OR_RETURN_IMPL(PLX_STATUS_CONCAT(plx_statusor_, __LINE__), lhs, expr)
#define PLX_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                              \
  if (!tmp.ok()) return std::move(tmp).status();  \
  lhs = std::move(tmp).value()
