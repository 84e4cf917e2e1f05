#pragma once
// The two kinds of error the pipeline raises for what a user gave it; the command line maps them
// to exit codes 1 (data) and 2 (usage).

#include <stdexcept>

namespace seqloc::pipeline {

/// Input data that cannot be used (a malformed file, a bad row); the message names the file, line
/// or cell and what is wrong.
class DataError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A request that cannot be carried out as given (bad option values, absurd region, output in
/// the way). Raised before any work is done.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace seqloc::pipeline
