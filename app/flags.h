// A small command-line flag parser for plenoxd and the plenox subcommands: `--name value` or
// `--name=value`, boolean switches, typed values with range errors, and generated --help.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace plx {

class FlagSet {
 public:
  FlagSet(std::string command, std::string summary)
      : command_(std::move(command)), summary_(std::move(summary)) {}

  // Declares a flag taking a value; `value_name` appears in the help (e.g. "DIR").
  FlagSet& Add(const std::string& name, const std::string& value_name, const std::string& help,
               std::optional<std::string> default_value = std::nullopt, bool required = false);
  // Declares a switch (present = true).
  FlagSet& AddSwitch(const std::string& name, const std::string& help);

  // Parses args (without the program and command names). Returns false (with the help in
  // `help_text`) when --help was given.
  absl::StatusOr<bool> Parse(const std::vector<std::string>& args);

  std::string Usage() const;

  bool Has(const std::string& name) const;  // given on the command line or has a default
  bool IsSet(const std::string& name) const { return values_.count(name) > 0; }  // given
  std::string GetString(const std::string& name) const;
  absl::StatusOr<int> GetInt(const std::string& name, int min_value, int max_value) const;
  absl::StatusOr<double> GetDouble(const std::string& name, double min_value,
                                   double max_value) const;
  bool GetSwitch(const std::string& name) const;

  const std::string& command() const { return command_; }

 private:
  void Declare(const std::string& name);  // aborts on a second declaration of `name`

  struct Flag {
    std::string value_name;
    std::string help;
    std::optional<std::string> default_value;
    bool required = false;
    bool is_switch = false;
  };
  std::string command_;
  std::string summary_;
  std::vector<std::string> order_;
  std::map<std::string, Flag> flags_;
  std::map<std::string, std::string> values_;
};

}  // namespace plx
