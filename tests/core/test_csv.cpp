// The one CSV reader and writer: RFC 4180's quoting both ways, line numbers for errors, and any
// text round-tripping through a record.

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "seqloc/core/csv.hpp"
#include "seqloc/core/error.hpp"

namespace seqloc::core {
namespace {

std::vector<CsvRecord> read_all(const std::string& text, CsvReader::Options options = {}) {
  std::istringstream in(text);
  CsvReader reader(in, "t.csv", options);
  std::vector<CsvRecord> records;
  while (auto record = reader.next()) records.push_back(std::move(*record));
  return records;
}

using Fields = std::vector<std::string>;

TEST(Csv, ReadsQuotedFieldsAsRfc4180Has) {
  const auto r = read_all("a,b,c\r\n\"x,1\",\"say \"\"hi\"\"\",\n\"two\nlines\",,z\n");
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r[0].fields, (Fields{"a", "b", "c"}));
  EXPECT_EQ(r[1].fields, (Fields{"x,1", "say \"hi\"", ""}));
  EXPECT_EQ(r[2].fields, (Fields{"two\nlines", "", "z"}));
  EXPECT_EQ(r[0].line, 1);
  EXPECT_EQ(r[1].line, 2);
  EXPECT_EQ(r[2].line, 3) << "the line a record starts on";
}

TEST(Csv, SkipsABomAndBlankLinesAndTrimsWhenAsked) {
  const auto r = read_all(
      "\xEF\xBB\xBF"
      "a, b\n  \n x , \" y \" \n",
      {.trim_blanks = true});
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].fields, (Fields{"a", "b"}));
  EXPECT_EQ(r[1].fields, (Fields{"x", " y "})) << "blanks inside quotes are the field's";
  EXPECT_EQ(r[1].line, 3);
  const auto kept = read_all(" x , y\n");
  EXPECT_EQ(kept[0].fields, (Fields{" x ", " y"})) << "without trimming blanks are text";
}

TEST(Csv, AnOpenQuoteNamesTheFileAndLine) {
  try {
    (void)read_all("a\n\"open,\nstill open\n");
    FAIL() << "no error";
  } catch (const DataError& e) {
    EXPECT_STREQ(e.what(), "t.csv:2: unterminated quoted field");
    EXPECT_EQ(e.category(), ErrorCategory::data);
  }
}

TEST(Csv, AnyTextRoundTripsThroughARecord) {
  const Fields fields{"cam,0", "", "\"quoted\"", " lead", "trail ", "multi\nline", "plain", "a\"b", "\t"};
  const std::string record = csv_record(fields);
  const auto back = read_all(record);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].fields, fields) << record;
  EXPECT_EQ(csv_field("plain"), "plain");
  EXPECT_EQ(csv_field("cam,0"), "\"cam,0\"");
  EXPECT_EQ(csv_field("a\"b"), "\"a\"\"b\"");
}

}  // namespace
}  // namespace seqloc::core
