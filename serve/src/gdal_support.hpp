#pragma once
// What serve's GDAL code shares (geotiff.cpp, web_mercator.cpp): registration, the last error's
// message, and option lists and datasets released on scope exit.

#include <mutex>
#include <string>
#include <utility>

#include <cpl_error.h>
#include <cpl_string.h>
#include <gdal.h>

namespace seqloc::serve::detail {

inline void register_gdal() {
  static std::once_flag once;
  std::call_once(once, [] { GDALAllRegister(); });
}

inline std::string gdal_message() {
  const char* m = CPLGetLastErrorMsg();
  return m && *m ? m : "unknown GDAL error";
}

/// CSL option lists freed on scope exit.
class Options {
 public:
  Options() = default;
  ~Options() { CSLDestroy(list_); }
  Options(const Options&) = delete;
  Options& operator=(const Options&) = delete;
  Options& set(const char* key, const std::string& value) {
    list_ = CSLSetNameValue(list_, key, value.c_str());
    return *this;
  }
  [[nodiscard]] char** get() const { return list_; }

 private:
  char** list_ = nullptr;
};

/// A GDAL dataset closed on scope exit (which flushes it).
class Dataset {
 public:
  explicit Dataset(GDALDatasetH h) : h_(h) {}
  ~Dataset() { close(); }
  Dataset(const Dataset&) = delete;
  Dataset& operator=(const Dataset&) = delete;
  Dataset(Dataset&& other) noexcept : h_(std::exchange(other.h_, nullptr)) {}
  Dataset& operator=(Dataset&&) = delete;
  [[nodiscard]] GDALDatasetH get() const { return h_; }
  explicit operator bool() const { return h_ != nullptr; }
  /// Closes now; false when GDAL reported a failure while flushing.
  bool close() {
    if (!h_) return true;
    CPLErrorReset();
    GDALClose(h_);
    h_ = nullptr;
    return CPLGetLastErrorType() < CE_Failure;
  }

 private:
  GDALDatasetH h_;
};

}  // namespace seqloc::serve::detail
