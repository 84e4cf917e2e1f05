#pragma once
// CSV as RFC 4180 has it, read and written in one place, so that every file seqloc reads
// (frames.csv, poses.csv, beliefs.csv) and writes round-trips any text: fields separated by
// commas, quoted with '"' when they hold a comma, a quote or a line break ("" is a quote inside
// quotes), records ended by LF or CRLF.

#include <istream>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace seqloc::core {

struct CsvRecord {
  int line = 0;  ///< the line the record starts on (the first line is 1)
  std::vector<std::string> fields;
};

class CsvReader {
 public:
  struct Options {
    /// Blanks (spaces, tabs) around an unquoted field, and between a quoted field's quotes and
    /// the commas, are dropped (frames.csv is often written by hand).
    bool trim_blanks = false;
  };
  /// Reads `in`; `name` (the file) begins every error message. A UTF-8 byte order mark before
  /// the first record is skipped.
  CsvReader(std::istream& in, std::string name, Options options);
  CsvReader(std::istream& in, std::string name) : CsvReader(in, std::move(name), Options{}) {}

  /// The next record; nothing at the end of the input. Lines holding only blanks are skipped.
  /// Throws DataError "NAME:LINE: unterminated quoted field" for a quote left open at the end.
  [[nodiscard]] std::optional<CsvRecord> next();

  [[nodiscard]] const std::string& name() const { return name_; }

 private:
  std::istream& in_;
  std::string name_;
  Options options_;
  int line_ = 0;
};

/// `text` as one CSV field: as it is, or quoted when it holds a comma, a quote, a line break or
/// blanks at either end.
[[nodiscard]] std::string csv_field(std::string_view text);

/// The fields as one record: each csv_field, joined by commas, ended by a line feed.
[[nodiscard]] std::string csv_record(std::span<const std::string> fields);

}  // namespace seqloc::core
