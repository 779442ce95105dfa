#include "app/flags.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx {

void FlagSet::Declare(const std::string& name) {
  if (flags_.count(name)) {
    // A programming error: two pieces of one command claim the same flag.
    std::fprintf(stderr, "%s: flag --%s declared twice\n", command_.c_str(), name.c_str());
    std::abort();
  }
  order_.push_back(name);
}

FlagSet& FlagSet::Add(const std::string& name, const std::string& value_name,
                      const std::string& help, std::optional<std::string> default_value,
                      bool required) {
  Declare(name);
  flags_[name] = Flag{value_name, help, std::move(default_value), required, false};
  return *this;
}

FlagSet& FlagSet::AddSwitch(const std::string& name, const std::string& help) {
  Declare(name);
  flags_[name] = Flag{"", help, std::nullopt, false, true};
  return *this;
}

absl::StatusOr<bool> FlagSet::Parse(const std::vector<std::string>& args) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg == "--help" || arg == "-h") return false;
    if (arg.rfind("--", 0) != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("unexpected argument \"", arg, "\" (flags start with --)"));
    }
    std::string name = arg.substr(2), value;
    bool has_value = false;
    if (const size_t eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      has_value = true;
    }
    const auto it = flags_.find(name);
    if (it == flags_.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat("unknown flag --", name, " for '", command_, "' (see --help)"));
    }
    if (it->second.is_switch) {
      if (has_value) {
        return absl::InvalidArgumentError(absl::StrCat("--", name, " takes no value"));
      }
      values_[name] = "1";
      continue;
    }
    if (!has_value) {
      if (i + 1 >= args.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("--", name, " needs a value (", it->second.value_name, ")"));
      }
      value = args[++i];
    }
    values_[name] = value;
  }
  for (const auto& [name, flag] : flags_) {
    if (flag.required && !values_.count(name)) {
      return absl::InvalidArgumentError(
          absl::StrCat("missing required flag --", name, " ", flag.value_name, " (see --help)"));
    }
  }
  return true;
}

std::string FlagSet::Usage() const {
  std::string out = absl::StrCat("usage: ", command_, " [flags]\n\n", summary_, "\n\nflags:\n");
  for (const std::string& name : order_) {
    const Flag& f = flags_.at(name);
    std::string left =
        absl::StrCat("  --", name, f.is_switch ? "" : absl::StrCat(" ", f.value_name));
    std::string right = f.help;
    if (f.required) absl::StrAppend(&right, " (required)");
    if (f.default_value && !f.default_value->empty()) {
      absl::StrAppend(&right, " [default: ", *f.default_value, "]");
    }
    absl::StrAppend(&out, absl::StrFormat("%-28s %s\n", left, right));
  }
  absl::StrAppend(&out, absl::StrFormat("%-28s %s\n", "  --help", "show this help"));
  return out;
}

bool FlagSet::Has(const std::string& name) const {
  if (values_.count(name)) return true;
  const auto it = flags_.find(name);
  return it != flags_.end() && it->second.default_value.has_value();
}

std::string FlagSet::GetString(const std::string& name) const {
  if (const auto v = values_.find(name); v != values_.end()) return v->second;
  const auto it = flags_.find(name);
  return it != flags_.end() && it->second.default_value ? *it->second.default_value : "";
}

absl::StatusOr<int> FlagSet::GetInt(const std::string& name, int min_value, int max_value) const {
  const std::string text = GetString(name);
  int v = 0;
  if (!absl::SimpleAtoi(text, &v)) {
    return absl::InvalidArgumentError(absl::StrCat("--", name, ": not an integer: \"", text, "\""));
  }
  if (v < min_value || v > max_value) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, " must be in [", min_value, ", ", max_value, "], got ", v));
  }
  return v;
}

absl::StatusOr<double> FlagSet::GetDouble(const std::string& name, double min_value,
                                          double max_value) const {
  const std::string text = GetString(name);
  double v = 0;
  if (!absl::SimpleAtod(text, &v) || !std::isfinite(v)) {
    return absl::InvalidArgumentError(absl::StrCat("--", name, ": not a number: \"", text, "\""));
  }
  if (v < min_value || v > max_value) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, " must be in [", min_value, ", ", max_value, "], got ", v));
  }
  return v;
}

bool FlagSet::GetSwitch(const std::string& name) const { return values_.count(name) > 0; }

}  // namespace plx
