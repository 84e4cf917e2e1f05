#pragma once
// calibration.json (docs/localize.md): a backbone's calibration as `seqloc calibrate` writes
// it and `seqloc localize --calibration` and the Python module read it. Its one writer and its
// one reader.

#include <cstddef>
#include <filesystem>
#include <string>

namespace seqloc::io {

/// {"format": "seqloc-calibration", "version": 1, "temperature", "blur_cells", "blur_bins",
/// "floor", "nll", "uniform_nll", "as_given_nll", "frames", "skipped"}: the calibration applied to
/// a volume (its temperature, blur and floor) and how the fit went (the mean NLL of the true cell
/// with it, for a uniform volume and for the volumes as given; the frames it read and skipped).
struct CalibrationFile {
  double temperature = 1;
  double blur_cells = 0;
  double blur_bins = 0;
  double floor = 0;
  double nll = 0;
  double uniform_nll = 0;
  double as_given_nll = 0;
  std::size_t frames = 0;
  std::size_t skipped = 0;
};

/// The file's text (indented JSON, a newline at the end).
[[nodiscard]] std::string calibration_file_json(const CalibrationFile& calibration);

/// Reads a calibration.json: its format, version and the four numbers applied (temperature,
/// blur_cells, blur_bins, floor; the fit's figures when present). Throws DataError naming the file
/// and what is wrong; the values' ranges are the reader's caller's to check.
[[nodiscard]] CalibrationFile read_calibration_file(const std::filesystem::path& path);

}  // namespace seqloc::io
