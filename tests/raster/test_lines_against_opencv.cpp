// Our lines against the drawing OrienterNet's rasterizer uses: OpenCV's cv::polylines, 8-connected,
// 1 px, on integer vertices (OrienterNet rounds its pixel coordinates before drawing). Every vertex
// stays inside the canvas, where OpenCV does not clip, so the two must agree cell for cell.

#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "seqloc/raster/rasterize.hpp"

namespace seqloc::raster {
namespace {

constexpr int kSide = 64;

cv::Mat opencv_polyline(const std::vector<Pixel>& points, bool closed) {
  cv::Mat canvas = cv::Mat::zeros(kSide, kSide, CV_8U);
  std::vector<cv::Point> cv_points;
  cv_points.reserve(points.size());
  for (const Pixel& p : points) cv_points.emplace_back(static_cast<int>(p.u), static_cast<int>(p.v));
  cv::polylines(canvas, cv_points, closed, 255, 1, cv::LINE_8);
  return canvas;
}

cv::Mat our_polyline(const std::vector<Pixel>& points, bool closed) {
  cv::Mat canvas = cv::Mat::zeros(kSide, kSide, CV_8U);
  const Window window{0, 0, kSide, kSide};
  auto plot = [&](std::int64_t u, std::int64_t v) { canvas.at<std::uint8_t>(static_cast<int>(v), static_cast<int>(u)) = 255; };
  if (closed) {
    for_each_ring_cell(std::span<const Pixel>(points), window, plot);
  } else {
    for_each_polyline_cell(std::span<const Pixel>(points), window, plot);
  }
  return canvas;
}

int differing_cells(const cv::Mat& a, const cv::Mat& b) { return cv::countNonZero(a != b); }

TEST(LinesAgainstOpenCV, ShortSegmentsInEveryDirection) {
  // Short segments are where exact ties are most frequent.
  std::mt19937 rng(2026);
  std::uniform_int_distribution<int> centre(12, kSide - 13);
  std::uniform_int_distribution<int> delta(-10, 10);
  int disagreements = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    const Pixel a{centre(rng), centre(rng)};
    const Pixel b{a.u + delta(rng), a.v + delta(rng)};
    const std::vector<Pixel> segment{a, b};
    if (differing_cells(opencv_polyline(segment, false), our_polyline(segment, false)) != 0) {
      ++disagreements;
      ADD_FAILURE() << "segment " << a.u << "," << a.v << " -> " << b.u << "," << b.v;
      if (disagreements > 5) break;
    }
  }
  EXPECT_EQ(disagreements, 0);
}

TEST(LinesAgainstOpenCV, LongPolylinesAndClosedRings) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> coordinate(0, kSide - 1);
  for (int trial = 0; trial < 300; ++trial) {
    std::vector<Pixel> points(2 + trial % 7);
    for (auto& p : points) p = {coordinate(rng), coordinate(rng)};
    for (const bool closed : {false, true}) {
      EXPECT_EQ(differing_cells(opencv_polyline(points, closed), our_polyline(points, closed)), 0)
          << "trial " << trial << (closed ? " (closed)" : " (open)");
    }
  }
}

}  // namespace
}  // namespace seqloc::raster
