#include "seqloc/core/csv.hpp"

#include <algorithm>

#include "seqloc/core/error.hpp"

namespace seqloc::core {
namespace {

bool blank(char c) { return c == ' ' || c == '\t'; }

bool only_blanks(const std::string& text) { return std::all_of(text.begin(), text.end(), blank); }

}  // namespace

CsvReader::CsvReader(std::istream& in, std::string name, Options options)
    : in_(in), name_(std::move(name)), options_(options) {}

std::optional<CsvRecord> CsvReader::next() {
  std::string text;
  do {
    if (!std::getline(in_, text)) return std::nullopt;
    ++line_;
    if (!text.empty() && text.back() == '\r') text.pop_back();
    if (line_ == 1 && text.rfind("\xEF\xBB\xBF", 0) == 0) text.erase(0, 3);
  } while (only_blanks(text));

  CsvRecord record{line_, {std::string()}};
  // Per field: before its first character, inside quotes, after the closing quote, or unquoted.
  enum class State { start, quoted, after_quote, plain } state = State::start;
  std::string pending_blanks;  // blanks of an unquoted field, kept only if more text follows
  for (;;) {
    for (std::size_t i = 0; i < text.size(); ++i) {
      const char c = text[i];
      std::string& field = record.fields.back();
      switch (state) {
        case State::quoted:
          if (c == '"' && i + 1 < text.size() && text[i + 1] == '"') {
            field += '"';
            ++i;
          } else if (c == '"') {
            state = State::after_quote;
          } else {
            field += c;
          }
          break;
        case State::start:
        case State::plain:
        case State::after_quote:
          if (c == ',') {
            record.fields.emplace_back();
            pending_blanks.clear();
            state = State::start;
          } else if (state == State::start && c == '"') {
            state = State::quoted;
          } else if (options_.trim_blanks && blank(c)) {
            if (state == State::plain) pending_blanks += c;
          } else {
            // After a closing quote, text before the comma belongs to the field (as readers
            // that are lenient about it keep it).
            field += pending_blanks;
            pending_blanks.clear();
            field += c;
            if (state == State::start) state = State::plain;
          }
          break;
      }
    }
    if (state != State::quoted) break;
    // A line break inside quotes belongs to the field; the record goes on on the next line.
    if (!std::getline(in_, text)) {
      throw DataError(name_ + ":" + std::to_string(record.line) + ": unterminated quoted field");
    }
    ++line_;
    if (!text.empty() && text.back() == '\r') text.pop_back();
    record.fields.back() += '\n';
  }
  return record;
}

std::string csv_field(std::string_view text) {
  const bool plain = text.find_first_of(",\"\n\r") == std::string_view::npos &&
                     (text.empty() || (!blank(text.front()) && !blank(text.back())));
  if (plain) return std::string(text);
  std::string quoted = "\"";
  for (const char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + '"';
}

std::string csv_record(std::span<const std::string> fields) {
  std::string record;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    if (i > 0) record += ',';
    record += csv_field(fields[i]);
  }
  return record + '\n';
}

}  // namespace seqloc::core
