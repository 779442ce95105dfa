// Whitespace-separated text files (TUM index files, trajectories, intrinsics.txt, ScanNet
// poses), read into rows that remember their 1-based line numbers so that every parse error
// can say "file:line: what is wrong".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace plx {

struct TextRow {
  int line_number = 0;  // 1-based, counting comment and blank lines too
  std::vector<std::string> fields;
};

// A parsed file: `path` is kept for error messages.
struct TextTable {
  std::string path;
  std::vector<TextRow> rows;
};

// Reads `path`, dropping blank lines and lines whose first non-blank character is '#'. Fields
// are split on spaces and tabs; a trailing '\r' (Windows line ends) is ignored.
// NotFoundError when the file does not exist.
absl::StatusOr<TextTable> ReadTextTable(const std::string& path);

// InvalidArgumentError "path:line: message".
absl::Status LineError(const std::string& path, int line_number, absl::string_view message);

// Errors unless `row` has exactly `count` fields; the message reads
// "path:line: expected <count> <what>, got <n>" (what: "numbers", "fields (t filename)", ...).
absl::Status ExpectFieldCount(const TextTable& table, const TextRow& row, size_t count,
                              absl::string_view what);

// Field `index` of `row` as a number; non-numeric and (unless allowed) non-finite values are
// errors naming the file, line and field (1-based).
absl::StatusOr<double> ParseDoubleField(const TextTable& table, const TextRow& row, size_t index,
                                        bool allow_non_finite = false);
absl::StatusOr<int64_t> ParseIntField(const TextTable& table, const TextRow& row, size_t index);

// Fields [first, first + count) as numbers (same rules as ParseDoubleField).
absl::StatusOr<std::vector<double>> ParseDoubleFields(const TextTable& table, const TextRow& row,
                                                      size_t first, size_t count,
                                                      bool allow_non_finite = false);

// Shortest text that parses back to exactly `value` (so written files round-trip bit-exactly
// without printing 535.39999999999998 for 535.4).
std::string FormatShortest(double value);

}  // namespace plx
