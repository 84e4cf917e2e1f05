#pragma once
// Pose likelihood volumes as NumPy .npy files (conventions.md section 4): float32 or float16,
// little-endian, C order, shape (H, W, N). The file is memory-mapped: nothing is copied until the
// filter's intake reads it.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/core/volume.hpp"

namespace seqloc::io {

/// A 3-D array of a .npy file, float32 or float16, little-endian, C order, memory-mapped: the
/// shape as its header gives it, whatever its axes mean (a volume's (H, W, N), beliefs.npy's
/// (frames, H, W)).
class NpyArray {
 public:
  /// Maps and validates `path`. Throws DataError naming the file for a missing or empty file, a
  /// bad magic or header, another dtype than <f4 / <f2, Fortran order, a shape that is not 3-D
  /// with positive sizes, or data that does not match the shape (checked before anything is
  /// allocated or mapped beyond the header).
  explicit NpyArray(const std::filesystem::path& path);
  ~NpyArray();
  NpyArray(NpyArray&& other) noexcept;
  NpyArray& operator=(NpyArray&& other) noexcept;
  NpyArray(const NpyArray&) = delete;
  NpyArray& operator=(const NpyArray&) = delete;

  /// The size of axis 0, 1 or 2.
  [[nodiscard]] int extent(int axis) const { return shape_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] core::VolumeType type() const { return type_; }
  [[nodiscard]] const void* data() const { return data_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  void release();

  std::filesystem::path path_;
  void* mapping_ = nullptr;
  std::size_t mapping_bytes_ = 0;
  const void* data_ = nullptr;
  std::array<int, 3> shape_{};
  core::VolumeType type_ = core::VolumeType::float32;
};

/// A frame's pose likelihood volume (conventions.md section 4): an NpyArray of shape (H, W, N).
class NpyVolume : public NpyArray {
 public:
  using NpyArray::NpyArray;

  [[nodiscard]] int height() const { return extent(0); }
  [[nodiscard]] int width() const { return extent(1); }
  [[nodiscard]] int bins() const { return extent(2); }

  /// The volume as the filter takes it.
  [[nodiscard]] core::FrameVolume view(core::VolumeValues values, double cell_m) const {
    return {data(), type(), values, height(), width(), bins(), cell_m};
  }
};

/// A C-order float32 array of shape (d0, d1, d2) as the bytes of a .npy file (format 1.0), which
/// NpyVolume reads back.
[[nodiscard]] std::string encode_npy_float32(int d0, int d1, int d2, const float* data);
/// The same for float16 values given as their IEEE half bits (core::float_to_half).
[[nodiscard]] std::string encode_npy_float16(int d0, int d1, int d2, const std::uint16_t* halves);

/// Largest volume accepted: 2^31 cells (8 GB of float32), far beyond any backbone's output.
inline constexpr std::uint64_t kMaxVolumeCells = 1ull << 31;

}  // namespace seqloc::io
