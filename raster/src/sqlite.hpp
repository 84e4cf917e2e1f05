#pragma once
// Minimal RAII over the SQLite C API for the cache (private to the raster module).

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include <sqlite3.h>


namespace seqloc::raster::detail {

class Database {
 public:
  Database(const std::string& path, int flags);
  ~Database();
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;

  [[nodiscard]] sqlite3* get() const { return db_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  void exec(std::string_view sql) const;
  [[nodiscard]] bool has_table(std::string_view name) const;
  [[noreturn]] void fail(std::string_view what) const;

 private:
  sqlite3* db_ = nullptr;
  std::string path_;
};

class Statement {
 public:
  Statement(const Database& db, std::string_view sql);
  ~Statement();
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  Statement& bind(int index, std::int64_t value);
  Statement& bind(int index, double value);
  Statement& bind(int index, std::string_view text);
  Statement& bind_blob(int index, std::span<const std::uint8_t> blob);
  Statement& bind_null(int index);
  /// Steps once: true while a row is available.
  bool step();
  void run() {
    while (step()) {
    }
    reset();
  }
  void reset();

  [[nodiscard]] std::int64_t column_int(int i) const { return sqlite3_column_int64(stmt_, i); }
  [[nodiscard]] double column_double(int i) const { return sqlite3_column_double(stmt_, i); }
  [[nodiscard]] std::string column_text(int i) const;
  [[nodiscard]] std::span<const std::uint8_t> column_blob(int i) const;
  [[nodiscard]] bool column_is_null(int i) const { return sqlite3_column_type(stmt_, i) == SQLITE_NULL; }

 private:
  const Database& db_;
  sqlite3_stmt* stmt_ = nullptr;
};

}  // namespace seqloc::raster::detail
