#pragma once
// The one base of every error seqloc raises for what it was given or what it met, with a category
// that says whose fault it is. The command line maps the category to an exit code, the HTTP
// service to a status and the Python module to an exception class, each once and by the category
// alone; every library raises its own classes (CacheError, FilterError, ...) under this base.

#include <stdexcept>
#include <string>

namespace seqloc {

enum class ErrorCategory {
  usage,      ///< a request that cannot be carried out as given: an option, a value, an output in the way
  not_found,  ///< a request for what is not there: a tile or point outside the region, an unknown region
  data,       ///< input that cannot be used: a malformed file, a bad row, a value out of range
  io,         ///< a file or device that cannot be opened, read or written
  internal,   ///< a broken invariant of seqloc itself
};

/// "usage", "not_found", "data", "io" or "internal".
[[nodiscard]] constexpr const char* category_name(ErrorCategory category) {
  switch (category) {
    case ErrorCategory::usage:
      return "usage";
    case ErrorCategory::not_found:
      return "not_found";
    case ErrorCategory::data:
      return "data";
    case ErrorCategory::io:
      return "io";
    case ErrorCategory::internal:
      return "internal";
  }
  return "internal";
}

/// The base: a message naming the file, line, tile or option concerned, and a category.
class Error : public std::runtime_error {
 public:
  Error(ErrorCategory category, const std::string& message) : std::runtime_error(message), category_(category) {}
  [[nodiscard]] ErrorCategory category() const noexcept { return category_; }

 private:
  ErrorCategory category_;
};

/// Input data that cannot be used (a malformed file, a bad row); the message names the file, line
/// or cell and what is wrong.
class DataError : public Error {
 public:
  explicit DataError(const std::string& message) : Error(ErrorCategory::data, message) {}
};

/// A request that cannot be carried out as given (bad option values, absurd region, output in
/// the way). Raised before any work is done.
class UsageError : public Error {
 public:
  explicit UsageError(const std::string& message) : Error(ErrorCategory::usage, message) {}
};

/// A request for what is not there (a tile outside the region, a region the server does not hold);
/// the message names what was asked for and what there is.
class NotFoundError : public Error {
 public:
  explicit NotFoundError(const std::string& message) : Error(ErrorCategory::not_found, message) {}
};

/// A file that cannot be opened, read or written; the message names it.
class IoError : public Error {
 public:
  explicit IoError(const std::string& message) : Error(ErrorCategory::io, message) {}
};

/// The category of any exception: a seqloc::Error's own, anything else internal (an exception
/// from the standard library or a dependency that no seqloc boundary turned into an Error).
[[nodiscard]] inline ErrorCategory category_of(const std::exception& e) {
  if (const auto* error = dynamic_cast<const Error*>(&e)) return error->category();
  return ErrorCategory::internal;
}

}  // namespace seqloc
