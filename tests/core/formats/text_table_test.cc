#include "core/formats/text_table.h"

#include <cmath>
#include <limits>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "tests/io_fixtures.h"
#include "tests/test_util.h"

namespace plx {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;

// Suite names carry "Dataset" so the dataset test filter picks them up.
TEST(DatasetTextTableTest, KeepsLineNumbersAndSkipsCommentsAndBlanks) {
  const std::string path = testing::MakeTempDir("text_table") + "/t.txt";
  testing::WriteTextFile(path, "# header\n\n  1 2\t3 \r\n   # indented comment\n4  five\n");
  auto table = ReadTextTable(path);
  ASSERT_TRUE(table.ok()) << table.status();
  ASSERT_EQ(table->rows.size(), 2u);
  EXPECT_EQ(table->rows[0].line_number, 3);
  EXPECT_THAT(table->rows[0].fields, ElementsAre("1", "2", "3"));
  EXPECT_EQ(table->rows[1].line_number, 5);
  EXPECT_THAT(table->rows[1].fields, ElementsAre("4", "five"));

  EXPECT_EQ(*ParseDoubleField(*table, table->rows[0], 2), 3.0);
  auto not_number = ParseDoubleField(*table, table->rows[1], 1);
  ASSERT_FALSE(not_number.ok());
  EXPECT_THAT(not_number.status().message(), HasSubstr("t.txt:5: field 2 is not a number"));
  auto count = ExpectFieldCount(*table, table->rows[1], 3, "numbers");
  EXPECT_THAT(count.message(), HasSubstr("t.txt:5: expected 3 numbers, got 2"));
  EXPECT_FALSE(ParseDoubleField(*table, table->rows[1], 7).ok());
}

TEST(DatasetTextTableTest, NonFiniteOnlyWhenAllowed) {
  TextTable table{"x.txt", {TextRow{4, {"inf", "-nan"}}}};
  EXPECT_FALSE(ParseDoubleField(table, table.rows[0], 0).ok());
  EXPECT_FALSE(ParseDoubleField(table, table.rows[0], 1).ok());
  auto inf = ParseDoubleField(table, table.rows[0], 0, /*allow_non_finite=*/true);
  ASSERT_TRUE(inf.ok());
  EXPECT_TRUE(std::isinf(*inf));
  auto nan = ParseDoubleField(table, table.rows[0], 1, /*allow_non_finite=*/true);
  ASSERT_TRUE(nan.ok());
  EXPECT_TRUE(std::isnan(*nan));
}

TEST(DatasetTextTableTest, MissingFileIsNotFound) {
  auto table = ReadTextTable("/nonexistent/plx/t.txt");
  ASSERT_FALSE(table.ok());
  EXPECT_EQ(table.status().code(), absl::StatusCode::kNotFound);
}

TEST(DatasetTextTableTest, FormatShortestRoundTrips) {
  for (double v : {535.4, 1.0 / 3.0, 1341841873.405959, -2.5e-300, 0.0, 6553.5}) {
    double parsed = 0;
    ASSERT_TRUE(absl::SimpleAtod(FormatShortest(v), &parsed));
    EXPECT_EQ(parsed, v);
  }
  EXPECT_EQ(FormatShortest(535.4), "535.4");
  EXPECT_EQ(FormatShortest(640), "640");
}

}  // namespace
}  // namespace plx
