#pragma once
// Pose likelihood volumes as NumPy .npy files (conventions.md section 4): float32 or float16,
// little-endian, C order, shape (H, W, N). The file is memory-mapped: nothing is copied until the
// filter's intake reads it.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/core/volume.hpp"

namespace seqloc::io {

class NpyVolume {
 public:
  /// Maps and validates `path`. Throws DataError naming the file for a missing or empty file, a
  /// bad magic or header, another dtype than <f4 / <f2, Fortran order, a shape that is not 3-D
  /// with positive sizes, or data that does not match the shape (checked before anything is
  /// allocated or mapped beyond the header).
  explicit NpyVolume(const std::filesystem::path& path);
  ~NpyVolume();
  NpyVolume(NpyVolume&& other) noexcept;
  NpyVolume& operator=(NpyVolume&& other) noexcept;
  NpyVolume(const NpyVolume&) = delete;
  NpyVolume& operator=(const NpyVolume&) = delete;

  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int bins() const { return bins_; }
  [[nodiscard]] core::VolumeType type() const { return type_; }
  [[nodiscard]] const void* data() const { return data_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

  /// The volume as the filter takes it.
  [[nodiscard]] core::FrameVolume view(core::VolumeValues values, double cell_m) const {
    return {data_, type_, values, height_, width_, bins_, cell_m};
  }

 private:
  void release();

  std::filesystem::path path_;
  void* mapping_ = nullptr;
  std::size_t mapping_bytes_ = 0;
  const void* data_ = nullptr;
  int height_ = 0, width_ = 0, bins_ = 0;
  core::VolumeType type_ = core::VolumeType::float32;
};

/// A C-order float32 array of shape (d0, d1, d2) as the bytes of a .npy file (format 1.0), which
/// NpyVolume reads back.
[[nodiscard]] std::string encode_npy_float32(int d0, int d1, int d2, const float* data);
/// The same for float16 values given as their IEEE half bits (core::float_to_half).
[[nodiscard]] std::string encode_npy_float16(int d0, int d1, int d2, const std::uint16_t* halves);

/// Largest volume accepted: 2^31 cells (8 GB of float32), far beyond any backbone's output.
inline constexpr std::uint64_t kMaxVolumeCells = 1ull << 31;

}  // namespace seqloc::io
