#include "core/formats/text_table.h"

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <system_error>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace plx {

absl::StatusOr<TextTable> ReadTextTable(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    return absl::NotFoundError(absl::StrCat(path, ": file not found"));
  }
  std::ifstream in(path);
  if (!in) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for reading"));

  TextTable table;
  table.path = path;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const absl::string_view content = absl::StripLeadingAsciiWhitespace(line);
    if (content.empty() || content.front() == '#') continue;
    TextRow row;
    row.line_number = line_number;
    row.fields = absl::StrSplit(content, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    table.rows.push_back(std::move(row));
  }
  if (in.bad()) return absl::DataLossError(absl::StrCat(path, ": read error"));
  return table;
}

absl::Status LineError(const std::string& path, int line_number, absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(path, ":", line_number, ": ", message));
}

absl::Status ExpectFieldCount(const TextTable& table, const TextRow& row, size_t count,
                              absl::string_view what) {
  if (row.fields.size() == count) return absl::OkStatus();
  return LineError(table.path, row.line_number,
                   absl::StrCat("expected ", count, " ", what, ", got ", row.fields.size()));
}

absl::StatusOr<double> ParseDoubleField(const TextTable& table, const TextRow& row, size_t index,
                                        bool allow_non_finite) {
  if (index >= row.fields.size()) {
    return LineError(table.path, row.line_number, absl::StrCat("missing field ", index + 1));
  }
  const std::string& text = row.fields[index];
  double value = 0;
  if (!absl::SimpleAtod(text, &value)) {
    return LineError(table.path, row.line_number,
                     absl::StrCat("field ", index + 1, " is not a number: \"", text, "\""));
  }
  if (!allow_non_finite && !std::isfinite(value)) {
    return LineError(table.path, row.line_number,
                     absl::StrCat("field ", index + 1, " is not finite: \"", text, "\""));
  }
  return value;
}

absl::StatusOr<int64_t> ParseIntField(const TextTable& table, const TextRow& row, size_t index) {
  if (index >= row.fields.size()) {
    return LineError(table.path, row.line_number, absl::StrCat("missing field ", index + 1));
  }
  const std::string& text = row.fields[index];
  int64_t value = 0;
  if (!absl::SimpleAtoi(text, &value)) {
    return LineError(table.path, row.line_number,
                     absl::StrCat("field ", index + 1, " is not an integer: \"", text, "\""));
  }
  return value;
}

absl::StatusOr<std::vector<double>> ParseDoubleFields(const TextTable& table, const TextRow& row,
                                                      size_t first, size_t count,
                                                      bool allow_non_finite) {
  std::vector<double> values;
  values.reserve(count);
  for (size_t i = first; i < first + count; ++i) {
    absl::StatusOr<double> value = ParseDoubleField(table, row, i, allow_non_finite);
    if (!value.ok()) return value.status();
    values.push_back(*value);
  }
  return values;
}

std::string FormatShortest(double value) {
  char buffer[64];
  const std::to_chars_result result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  if (result.ec != std::errc()) return absl::StrCat(value);  // cannot happen with 64 chars
  return std::string(buffer, result.ptr);
}

}  // namespace plx
