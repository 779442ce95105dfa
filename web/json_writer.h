// A small streaming JSON writer for the viewer's endpoints: the caller opens and closes objects
// and arrays, the writer places the commas and escapes strings. Numbers that are not finite
// are written as null (JSON has no NaN or infinity).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/strings/string_view.h"

namespace plx::web {

class JsonWriter {
 public:
  JsonWriter& BeginObject();
  JsonWriter& EndObject();
  JsonWriter& BeginArray();
  JsonWriter& EndArray();
  // The next member's name (inside an object).
  JsonWriter& Key(absl::string_view key);
  JsonWriter& String(absl::string_view value);
  JsonWriter& Number(double value);
  JsonWriter& Int(int64_t value);
  JsonWriter& Bool(bool value);
  JsonWriter& Null();
  // An array of numbers.
  JsonWriter& Numbers(const double* values, int count);

  const std::string& str() const { return out_; }

 private:
  void BeforeValue();

  std::string out_;
  // Per open container: whether it has a member yet; a key just written skips the comma.
  std::vector<bool> has_member_;
  bool after_key_ = false;
};

// `text` as a quoted JSON string.
std::string JsonQuote(absl::string_view text);

}  // namespace plx::web
