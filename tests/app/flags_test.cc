#include "app/flags.h"

#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/status/status.h"

namespace plx {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::Not;

// The flag set every test starts from: one of each kind the subcommands declare.
FlagSet MakeFlags() {
  FlagSet flags("plenox frob", "Frobnicates a dataset.");
  flags.Add("dataset", "DIR", "input folder", std::nullopt, /*required=*/true)
      .Add("every", "N", "use every N-th frame", "10")
      .Add("scale", "S", "a scale factor", "0.5")
      .Add("name", "TEXT", "an optional label")
      .AddSwitch("json", "print JSON");
  return flags;
}

TEST(FlagSetTest, AcceptsSpaceAndEqualsForms) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "/data/a", "--name=hello"}).value());
  EXPECT_EQ(flags.GetString("dataset"), "/data/a");
  EXPECT_EQ(flags.GetString("name"), "hello");
}

TEST(FlagSetTest, EqualsFormKeepsEverythingAfterTheFirstEquals) {
  // Values such as "a=b" (or an empty value) must survive intact: only the first '=' separates.
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset=x=y", "--name="}).value());
  EXPECT_EQ(flags.GetString("dataset"), "x=y");
  EXPECT_EQ(flags.GetString("name"), "");
  EXPECT_TRUE(flags.Has("name"));
}

TEST(FlagSetTest, ValueMayStartWithADash) {
  // Poses and offsets are often negative: "-0.5 ..." is a value, not a flag.
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d", "--name", "-0.5 1 2"}).value());
  EXPECT_EQ(flags.GetString("name"), "-0.5 1 2");
}

TEST(FlagSetTest, LaterValueWins) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d", "--every", "3", "--every=7"}).value());
  EXPECT_EQ(flags.GetInt("every", 1, 100).value(), 7);
}

TEST(FlagSetTest, SwitchIsFalseUnlessGiven) {
  FlagSet off = MakeFlags();
  ASSERT_TRUE(off.Parse({"--dataset", "d"}).value());
  EXPECT_FALSE(off.GetSwitch("json"));

  FlagSet on = MakeFlags();
  ASSERT_TRUE(on.Parse({"--json", "--dataset", "d"}).value());
  EXPECT_TRUE(on.GetSwitch("json"));
  // The switch must not swallow the next argument as its value.
  EXPECT_EQ(on.GetString("dataset"), "d");
}

TEST(FlagSetTest, SwitchGivenAValueIsAnError) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--dataset", "d", "--json=1"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(parsed.status().message(), AllOf(HasSubstr("--json"), HasSubstr("no value")));
}

TEST(FlagSetTest, UnknownFlagIsAnErrorNamingItAndTheCommand) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--dataset", "d", "--evrey", "3"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(parsed.status().message(), AllOf(HasSubstr("--evrey"), HasSubstr("frob")));
}

TEST(FlagSetTest, UnknownFlagInEqualsFormNamesOnlyTheFlag) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--colour=red", "--dataset", "d"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), AllOf(HasSubstr("--colour"), Not(HasSubstr("red"))));
}

TEST(FlagSetTest, PositionalArgumentIsAnError) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--dataset", "d", "stray"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), HasSubstr("stray"));
}

TEST(FlagSetTest, SingleDashFlagIsAnError) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"-dataset", "d"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), HasSubstr("-dataset"));
}

TEST(FlagSetTest, MissingValueIsAnError) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--dataset", "d", "--every"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
  // The message says which flag and what kind of value it wanted.
  EXPECT_THAT(parsed.status().message(),
              AllOf(HasSubstr("--every"), HasSubstr("needs a value"), HasSubstr("N")));
}

TEST(FlagSetTest, MissingRequiredFlagIsAnError) {
  FlagSet flags = MakeFlags();
  const absl::StatusOr<bool> parsed = flags.Parse({"--every", "3"});
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(parsed.status().message(), AllOf(HasSubstr("--dataset"), HasSubstr("required")));
}

TEST(FlagSetTest, EmptyArgumentListStillChecksRequiredFlags) {
  FlagSet flags = MakeFlags();
  EXPECT_FALSE(flags.Parse({}).ok());

  FlagSet optional_only("noop", "Needs nothing.");
  optional_only.Add("every", "N", "step", "1");
  EXPECT_TRUE(optional_only.Parse({}).value());
}

TEST(FlagSetTest, HelpReturnsFalseEvenWithoutRequiredFlags) {
  // --help must work on its own: asking how to call a command is never an error.
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--help"}, std::vector<std::string>{"-h"},
        std::vector<std::string>{"--every", "3", "--help"}}) {
    FlagSet flags = MakeFlags();
    const absl::StatusOr<bool> parsed = flags.Parse(args);
    ASSERT_TRUE(parsed.ok()) << parsed.status() << " for " << args.size() << " args";
    EXPECT_FALSE(*parsed);
  }
}

TEST(FlagSetTest, DefaultsApplyWhenNotGiven) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d"}).value());
  EXPECT_TRUE(flags.Has("every"));
  EXPECT_EQ(flags.GetString("every"), "10");
  EXPECT_EQ(flags.GetInt("every", 1, 100).value(), 10);
  EXPECT_DOUBLE_EQ(flags.GetDouble("scale", 0.0, 1.0).value(), 0.5);
  // No default and not given: absent, and reads as empty.
  EXPECT_FALSE(flags.Has("name"));
  EXPECT_EQ(flags.GetString("name"), "");
  EXPECT_FALSE(flags.Has("no-such-flag"));
}

TEST(FlagSetTest, GivenValueOverridesDefault) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d", "--every", "4", "--scale=0.25"}).value());
  EXPECT_EQ(flags.GetInt("every", 1, 100).value(), 4);
  EXPECT_DOUBLE_EQ(flags.GetDouble("scale", 0.0, 1.0).value(), 0.25);
}

TEST(FlagSetTest, GetIntAcceptsTheRangeBoundsInclusive) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d", "--every", "1"}).value());
  EXPECT_EQ(flags.GetInt("every", 1, 5).value(), 1);
  FlagSet upper = MakeFlags();
  ASSERT_TRUE(upper.Parse({"--dataset", "d", "--every", "5"}).value());
  EXPECT_EQ(upper.GetInt("every", 1, 5).value(), 5);
  FlagSet negative = MakeFlags();
  ASSERT_TRUE(negative.Parse({"--dataset", "d", "--every", "-3"}).value());
  EXPECT_EQ(negative.GetInt("every", -10, 10).value(), -3);
}

TEST(FlagSetTest, GetIntOutOfRangeNamesFlagRangeAndValue) {
  for (const char* value : {"0", "6", "-1"}) {
    FlagSet flags = MakeFlags();
    ASSERT_TRUE(flags.Parse({"--dataset", "d", "--every", value}).value());
    const absl::StatusOr<int> v = flags.GetInt("every", 1, 5);
    ASSERT_FALSE(v.ok()) << value;
    EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(v.status().message(),
                AllOf(HasSubstr("--every"), HasSubstr("[1, 5]"), HasSubstr(value)));
  }
}

TEST(FlagSetTest, GetIntRejectsNonIntegers) {
  // "3.5" and "1e3" are numbers but not integers; silently truncating them would hide typos,
  // and an int overflow must not wrap around.
  for (const char* value : {"abc", "3.5", "1e3", "", "12abc", "99999999999"}) {
    FlagSet flags = MakeFlags();
    ASSERT_TRUE(flags.Parse({"--dataset", "d", "--every", value}).value());
    const absl::StatusOr<int> v = flags.GetInt("every", 0, 2147483647);
    ASSERT_FALSE(v.ok()) << "\"" << value << "\" parsed as " << *v;
    EXPECT_THAT(v.status().message(), AllOf(HasSubstr("--every"), HasSubstr("integer")));
  }
}

TEST(FlagSetTest, GetDoubleParsesCommonForms) {
  for (const auto& [text, expected] : std::vector<std::pair<const char*, double>>{
           {"0.04", 0.04}, {"1e-3", 1e-3}, {"-2.5", -2.5}, {"7", 7.0}}) {
    FlagSet flags = MakeFlags();
    ASSERT_TRUE(flags.Parse({"--dataset", "d", "--scale", text}).value());
    const absl::StatusOr<double> v = flags.GetDouble("scale", -10.0, 10.0);
    ASSERT_TRUE(v.ok()) << text << ": " << v.status();
    EXPECT_DOUBLE_EQ(*v, expected) << text;
  }
}

TEST(FlagSetTest, GetDoubleRejectsNonNumbersAndNonFinite) {
  // NaN would slip through every range check (all comparisons are false), so it must be
  // refused as "not a number" before the range is looked at.
  for (const char* value : {"abc", "", "nan", "inf", "-inf", "0.5x"}) {
    FlagSet flags = MakeFlags();
    ASSERT_TRUE(flags.Parse({"--dataset", "d", "--scale", value}).value());
    const absl::StatusOr<double> v = flags.GetDouble("scale", -1e30, 1e30);
    ASSERT_FALSE(v.ok()) << "\"" << value << "\" parsed as " << *v;
    EXPECT_EQ(v.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(v.status().message(), AllOf(HasSubstr("--scale"), HasSubstr("not a number")));
  }
}

TEST(FlagSetTest, GetDoubleOutOfRangeNamesFlagAndRange) {
  FlagSet flags = MakeFlags();
  ASSERT_TRUE(flags.Parse({"--dataset", "d", "--scale", "1.5"}).value());
  const absl::StatusOr<double> v = flags.GetDouble("scale", 0.001, 1.0);
  ASSERT_FALSE(v.ok());
  EXPECT_THAT(v.status().message(),
              AllOf(HasSubstr("--scale"), HasSubstr("0.001"), HasSubstr("1.5")));
  // The bounds themselves are allowed.
  FlagSet edge = MakeFlags();
  ASSERT_TRUE(edge.Parse({"--dataset", "d", "--scale", "1"}).value());
  EXPECT_DOUBLE_EQ(edge.GetDouble("scale", 0.001, 1.0).value(), 1.0);
}

TEST(FlagSetTest, UsageListsEveryFlagWithDefaultsAndRequired) {
  const std::string usage = MakeFlags().Usage();
  EXPECT_THAT(usage, HasSubstr("usage: plenox frob"));
  EXPECT_THAT(usage, HasSubstr("Frobnicates a dataset."));
  // One line per flag: name, value name, help, then the marks.
  const auto line_of = [&usage](const std::string& flag) -> std::string {
    const size_t at = usage.find("  --" + flag + " ");
    if (at == std::string::npos) return "";
    return usage.substr(at, usage.find('\n', at) - at);
  };
  EXPECT_THAT(line_of("dataset"), AllOf(HasSubstr("DIR"), HasSubstr("input folder"),
                                        HasSubstr("(required)"), Not(HasSubstr("default"))));
  EXPECT_THAT(line_of("every"), AllOf(HasSubstr("N"), HasSubstr("use every N-th frame"),
                                      HasSubstr("[default: 10]"), Not(HasSubstr("required"))));
  EXPECT_THAT(line_of("scale"), HasSubstr("[default: 0.5]"));
  EXPECT_THAT(line_of("name"), AllOf(HasSubstr("TEXT"), HasSubstr("an optional label"),
                                     Not(HasSubstr("default")), Not(HasSubstr("required"))));
  EXPECT_THAT(line_of("json"), HasSubstr("print JSON"));
  EXPECT_THAT(usage, HasSubstr("--help"));
}

TEST(FlagSetTest, UsageKeepsDeclarationOrder) {
  // Commands declare their most important flags first; the help must show them that way.
  const std::string usage = MakeFlags().Usage();
  const size_t dataset = usage.find("--dataset");
  const size_t every = usage.find("--every");
  const size_t scale = usage.find("--scale");
  const size_t name = usage.find("--name");
  const size_t json = usage.find("--json");
  const size_t help = usage.find("--help");
  ASSERT_NE(help, std::string::npos);
  EXPECT_LT(dataset, every);
  EXPECT_LT(every, scale);
  EXPECT_LT(scale, name);
  EXPECT_LT(name, json);
  EXPECT_LT(json, help);
}

TEST(FlagSetTest, EmptyDefaultIsNotShown) {
  // "[default: ]" would read as a bug; an empty default is simply not mentioned.
  FlagSet flags("x", "y");
  flags.Add("label", "TEXT", "a label", "");
  EXPECT_THAT(flags.Usage(), Not(HasSubstr("[default: ]")));
}

}  // namespace
}  // namespace plx
