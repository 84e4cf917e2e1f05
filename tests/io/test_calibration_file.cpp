// calibration.json's one writer and one reader (io/calibration_file.hpp): a round trip of every
// field, an older file without the fit's figures, and one clear error for each thing wrong.

#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "seqloc/core/error.hpp"
#include "seqloc/io/calibration_file.hpp"
#include "support/test_support.hpp"

namespace seqloc::io {
namespace {

void write(const std::filesystem::path& path, const std::string& text) { std::ofstream(path) << text; }

// The message of the DataError that reading `path` throws ("" when nothing is thrown).
std::string refusal(const std::filesystem::path& path) {
  try {
    (void)read_calibration_file(path);
  } catch (const DataError& e) {
    return e.what();
  }
  return "";
}

TEST(CalibrationFile, EveryFieldRoundTrips) {
  test::ScratchDir dir;
  const CalibrationFile c{0.37, 1.5, 2, 1e-4, 3.25, 15.2, 4.75, 1200, 17};
  write(dir / "calibration.json", calibration_file_json(c));
  const CalibrationFile back = read_calibration_file(dir / "calibration.json");
  EXPECT_EQ(back.temperature, c.temperature);
  EXPECT_EQ(back.blur_cells, c.blur_cells);
  EXPECT_EQ(back.blur_bins, c.blur_bins);
  EXPECT_EQ(back.floor, c.floor);
  EXPECT_EQ(back.nll, c.nll);
  EXPECT_EQ(back.uniform_nll, c.uniform_nll);
  EXPECT_EQ(back.as_given_nll, c.as_given_nll);
  EXPECT_EQ(back.frames, c.frames);
  EXPECT_EQ(back.skipped, c.skipped);
}

TEST(CalibrationFile, TheFitsFiguresAreOptional) {
  test::ScratchDir dir;
  write(dir / "c.json", R"({"format": "seqloc-calibration", "version": 1, "temperature": 2, "blur_cells": 0,
                           "blur_bins": 1, "floor": 0.01})");
  const CalibrationFile c = read_calibration_file(dir / "c.json");
  EXPECT_EQ(c.temperature, 2);
  EXPECT_EQ(c.blur_bins, 1);
  EXPECT_EQ(c.floor, 0.01);
  EXPECT_EQ(c.frames, 0u);
}

TEST(CalibrationFile, EachThingWrongIsOneErrorNamingTheFile) {
  test::ScratchDir dir;
  const auto path = dir / "calibration.json";
  const std::string fields = R"("temperature": 2, "blur_cells": 0, "blur_bins": 0, "floor": 0)";
  const std::pair<std::string, std::string> cases[] = {
      {"{not json", "not JSON"},
      {R"({"format": "something else"})", "not a calibration file"},
      {R"({"format": "seqloc-calibration", "version": 2, )" + fields + "}", "calibration version 2"},
      {R"({"format": "seqloc-calibration", "version": 1, "temperature": "2", "blur_cells": 0, "blur_bins": 0,
          "floor": 0})",
       "'temperature' must be a number"},
      {R"({"format": "seqloc-calibration", "version": 1, "temperature": 2, "blur_cells": 0, "floor": 0})",
       "'blur_bins' must be a number"},
      {R"({"format": "seqloc-calibration", "version": 1, )" + fields + R"(, "frames": -3})",
       "'frames' must be a count"},
  };
  for (const auto& [text, why] : cases) {
    write(path, text);
    const std::string message = refusal(path);
    EXPECT_NE(message.find("calibration.json"), std::string::npos) << text << ": " << message;
    EXPECT_NE(message.find(why), std::string::npos) << text << ": " << message;
  }
  EXPECT_NE(refusal(dir / "missing.json").find("cannot read"), std::string::npos);
}

}  // namespace
}  // namespace seqloc::io
