#include "seqloc/pipeline/matcher.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "seqloc/osm/classes.hpp"
#include "flat_index.hpp"

namespace seqloc::pipeline {
namespace {

constexpr double kCellM = 0.5;

using detail::flat;

int class_count(int channel) { return static_cast<int>(osm::group_names(static_cast<osm::Channel>(channel)).size()); }

void require(bool ok, const char* field, double value, const char* rule) {
  if (ok) return;
  std::ostringstream s;
  s << "matcher: " << field << " = " << value << ": " << rule;
  throw std::invalid_argument(s.str());
}

// The array rotations by quarter turns (clockwise q times).
cv::Mat rotate_cw(const cv::Mat& m, int q) {
  cv::Mat out;
  switch (q & 3) {
    case 0:
      return m.clone();
    case 1:
      cv::rotate(m, out, cv::ROTATE_90_CLOCKWISE);
      break;
    case 2:
      cv::rotate(m, out, cv::ROTATE_180);
      break;
    default:
      cv::rotate(m, out, cv::ROTATE_90_COUNTERCLOCKWISE);
  }
  return out;
}

cv::Mat spectrum(const cv::Mat& image, int n) {
  cv::Mat padded = cv::Mat::zeros(n, n, CV_32F);
  image.copyTo(padded(cv::Rect(0, 0, image.cols, image.rows)));
  cv::Mat f;
  cv::dft(padded, f, 0, image.rows);
  return f;
}

}  // namespace

void MatcherConfig::validate() const {
  require(size >= 2 && size <= 1024 && size % 2 == 0, "size", size, "must be even, in [2, 1024]");
  require(headings >= 4 && headings <= 1024 && headings % 4 == 0, "headings", headings,
          "must be a multiple of 4 in [4, 1024]");
  require(std::isfinite(temperature) && temperature > 0, "temperature", temperature, "must be > 0");
  require(miss_rate > 0 && miss_rate < 1, "miss_rate", miss_rate, "must be in (0, 1)");
  require(spurious_rate > 0 && spurious_rate < 1, "spurious_rate", spurious_rate, "must be in (0, 1)");
  require(confusion_rate > 0 && miss_rate + confusion_rate < 1, "confusion_rate", confusion_rate,
          "must be > 0 with miss_rate + confusion_rate < 1");
  require(std::isfinite(tolerance_m) && tolerance_m >= 0 && tolerance_m <= 20, "tolerance_m", tolerance_m,
          "must be in [0, 20]");
  require(threads >= 1 && threads <= 256, "threads", threads, "must be in [1, 256]");
  calibration.validate();
}

BevMatcher::BevMatcher(const MatcherConfig& config) : config_(config) {
  config_.validate();
  for (int c = 0; c < 3; ++c) {
    const int k = class_count(c);
    auto& p = likelihood_[static_cast<std::size_t>(c)];
    const auto side = static_cast<std::size_t>(k) + 1;
    p.assign(side * side, 0.0);
    auto at = [&](int o, int m) -> double& { return p[flat(o, m, k + 1)]; };
    // Map background: seen as background, or a spurious detection of any class.
    at(0, 0) = 1 - config_.spurious_rate;
    for (int o = 1; o <= k; ++o) at(o, 0) = config_.spurious_rate / k;
    // Map class m: seen, missed, or confused with another class of the channel.
    for (int m = 1; m <= k; ++m) {
      for (int o = 0; o <= k; ++o) {
        at(o, m) = o == m ? 1 - config_.miss_rate - config_.confusion_rate
                          : (o == 0 ? config_.miss_rate : config_.confusion_rate / (k - 1));
      }
    }
  }
}

double BevMatcher::cell_score(int channel, int observed, std::span<const double> map_share) const {
  const auto& p = likelihood_[static_cast<std::size_t>(channel)];
  const int k = class_count(channel);
  double likelihood = 0;
  for (int m = 0; m <= k; ++m) likelihood += map_share[static_cast<std::size_t>(m)] * p[flat(observed, m, k + 1)];
  return std::log(likelihood) - std::log(p[flat(observed, 0, k + 1)]);
}

std::vector<float> BevMatcher::map_term(int channel, int observed, std::span<const std::uint8_t> map_rgb, int side) const {
  const auto cells = static_cast<std::size_t>(side) * static_cast<std::size_t>(side);
  if (map_rgb.size() != cells * 3) throw std::invalid_argument("matcher: the map crop's size does not match its side");
  const int k = class_count(channel);
  const auto& p = likelihood_[static_cast<std::size_t>(channel)];
  const double sigma = config_.tolerance_m / kCellM;
  // P(observed | x) = sum over map codes m of blur(indicator of m)(x) * P(observed | m); the
  // blurred indicators of a partition still sum to 1, so this is a mixture.
  std::vector<double> mixture(cells, 0.0);
  std::vector<char> present(static_cast<std::size_t>(k + 1), 0);
  for (std::size_t i = 0; i < cells; ++i) present[map_rgb[3 * i + static_cast<std::size_t>(channel)]] = 1;
  cv::Mat indicator(side, side, CV_32F);
  for (int m = 0; m <= k; ++m) {
    if (!present[static_cast<std::size_t>(m)]) continue;
    auto* ind = indicator.ptr<float>();
    for (std::size_t i = 0; i < cells; ++i) ind[i] = map_rgb[3 * i + static_cast<std::size_t>(channel)] == m ? 1.0f : 0.0f;
    if (sigma > 0) cv::GaussianBlur(indicator, indicator, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
    const double pm = p[flat(observed, m, k + 1)];
    ind = indicator.ptr<float>();
    for (std::size_t i = 0; i < cells; ++i) mixture[i] += static_cast<double>(ind[i]) * pm;
  }
  const double background = p[flat(observed, 0, k + 1)];
  const double floor = std::min(config_.spurious_rate / k, config_.confusion_rate / (k - 1)) * 1e-3;
  std::vector<float> term(cells);
  for (std::size_t i = 0; i < cells; ++i) {
    term[i] = static_cast<float>(std::log(std::max(mixture[i], floor)) - std::log(background));
  }
  return term;
}

std::vector<float> BevMatcher::rotated_template(const Observation& observation, int channel, int code,
                                                double heading_deg) const {
  const int t = observation.size;
  const double centre = (t - 1) / 2.0;
  // The indicator in the body frame, limited to the inscribed disc so that no rotation clips it.
  std::vector<float> body(observation.cells(), 0.0f);
  for (int r = 0; r < t; ++r) {
    for (int c = 0; c < t; ++c) {
      const auto i = flat(r, c, t);
      const double dr = r - centre, dc = c - centre;
      if (observation.visible[i] && observation.classes[3 * i + static_cast<std::size_t>(channel)] == code &&
          dr * dr + dc * dc <= centre * centre + 1e-9) {
        body[i] = 1.0f;
      }
    }
  }
  const double th = heading_deg * M_PI / 180.0, s = std::sin(th), c = std::cos(th);
  std::vector<float> out(observation.cells(), 0.0f);
  for (int row = 0; row < t; ++row) {
    for (int col = 0; col < t; ++col) {
      // North-up cell (east e, north n from the camera) -> body (forward f, right r).
      const double e = col - centre, n = centre - row;
      const double f = e * s + n * c, rt = e * c - n * s;
      const double br = centre - f, bc = centre + rt;
      const double r0 = std::floor(br), c0 = std::floor(bc);
      const double wr = br - r0, wc = bc - c0;
      double value = 0;
      for (int dr = 0; dr < 2; ++dr) {
        for (int dc = 0; dc < 2; ++dc) {
          const int rr = static_cast<int>(r0) + dr, cc = static_cast<int>(c0) + dc;
          if (rr < 0 || rr >= t || cc < 0 || cc >= t) continue;
          const double w = (dr ? wr : 1 - wr) * (dc ? wc : 1 - wc);
          value += w * body[flat(rr, cc, t)];
        }
      }
      out[flat(row, col, t)] = static_cast<float>(value);
    }
  }
  return out;
}

std::vector<std::array<int, 2>> BevMatcher::observed_codes(const Observation& observation) {
  std::vector<std::array<int, 2>> codes;
  for (int c = 0; c < 3; ++c) {
    std::vector<char> seen(256, 0);
    for (std::size_t i = 0; i < observation.cells(); ++i) {
      if (observation.visible[i]) seen[observation.classes[3 * i + static_cast<std::size_t>(c)]] = 1;
    }
    for (int code = 0; code < 256; ++code) {
      if (seen[static_cast<std::size_t>(code)]) codes.push_back({c, code});
    }
  }
  return codes;
}

std::vector<float> BevMatcher::match(const Observation& observation, std::span<const std::uint8_t> map_rgb) const {
  const int t = observation.size, s = config_.size, n_bins = config_.headings;
  const int side = map_side(t);
  if (t < 1 || t % 2 == 0 || observation.classes.size() != observation.cells() * 3 ||
      observation.visible.size() != observation.cells()) {
    throw std::invalid_argument("matcher: the observation must be square with an odd side");
  }
  if (map_rgb.size() != static_cast<std::size_t>(side) * static_cast<std::size_t>(side) * 3) {
    std::ostringstream m;
    m << "matcher: the map crop must be " << side << " x " << side << " cells for an observation of side " << t;
    throw std::invalid_argument(m.str());
  }
  const int n = cv::getOptimalDFTSize(side);
  const auto codes = observed_codes(observation);
  // The map term of every observed code, turned counter-clockwise by q quarter turns, transformed.
  std::vector<std::array<cv::Mat, 4>> map_spectra(codes.size());
  for (std::size_t o = 0; o < codes.size(); ++o) {
    auto term = map_term(codes[o][0], codes[o][1], map_rgb, side);
    const cv::Mat m(side, side, CV_32F, term.data());
    for (int q = 0; q < 4; ++q) map_spectra[o][static_cast<std::size_t>(q)] = spectrum(rotate_cw(m, -q), n);
  }

  std::vector<float> volume(static_cast<std::size_t>(s) * static_cast<std::size_t>(s) * static_cast<std::size_t>(n_bins));
  const int quarter = n_bins / 4;
  const auto scale = static_cast<float>(1.0 / config_.temperature);
  const auto plane = static_cast<std::size_t>(s) * static_cast<std::size_t>(s);
  // Slices go to the (H, W, N) volume a batch of consecutive headings at a time, so that each
  // cell's run of bins is written whole (one slice at a time would touch every cache line of
  // the volume once per heading).
  constexpr int kBatch = 16;
  auto work = [&](int j0, int j1) {
    std::array<cv::Mat, 4> acc;
    for (auto& a : acc) a.create(n, n, CV_32F);
    cv::Mat product, correlation;
    std::vector<float> batch(static_cast<std::size_t>(4 * kBatch) * plane);  // [q][heading - jb][v][u]
    for (int jb = j0; jb < j1; jb += kBatch) {
      const int je = std::min(j1, jb + kBatch);
      for (int j = jb; j < je; ++j) {
        for (auto& a : acc) a.setTo(0);
        const double heading = j * 360.0 / n_bins;
        for (std::size_t o = 0; o < codes.size(); ++o) {
          auto tmpl = rotated_template(observation, codes[o][0], codes[o][1], heading);
          const cv::Mat fa = spectrum(cv::Mat(t, t, CV_32F, tmpl.data()), n);
          for (std::size_t q = 0; q < 4; ++q) {
            cv::mulSpectrums(map_spectra[o][q], fa, product, 0, /*conjB=*/true);
            acc[q] += product;
          }
        }
        // corr(R_q A, M) = R_q corr(A, R_q^-1 M): heading + q quarter turns from one template.
        // Only the first s rows of the correlation are wanted.
        for (int q = 0; q < 4; ++q) {
          cv::dft(acc[static_cast<std::size_t>(q)], correlation, cv::DFT_INVERSE | cv::DFT_REAL_OUTPUT | cv::DFT_SCALE,
                  s);
          const cv::Mat slice = rotate_cw(correlation(cv::Rect(0, 0, s, s)), q);
          float* dst = batch.data() + (static_cast<std::size_t>(q) * kBatch + static_cast<std::size_t>(j - jb)) * plane;
          for (int v = 0; v < s; ++v) {
            const auto* row = slice.ptr<float>(v);
            std::copy(row, row + s, dst + static_cast<std::size_t>(v) * static_cast<std::size_t>(s));
          }
        }
      }
      const auto count = static_cast<std::size_t>(je - jb);
      for (std::size_t cell = 0; cell < plane; ++cell) {
        float* out = volume.data() + cell * static_cast<std::size_t>(n_bins);
        for (std::size_t q = 0; q < 4; ++q) {
          float* run = out + flat(static_cast<int>(q), jb, quarter);  // bins jb .. je - 1 of quarter q
          const float* src = batch.data() + q * kBatch * plane + cell;
          for (std::size_t k = 0; k < count; ++k) run[k] = src[k * plane] * scale;
        }
      }
    }
  };
  const int threads = std::max(1, std::min(config_.threads, quarter));
  {
    std::vector<std::jthread> workers;
    for (int w = 1; w < threads; ++w) workers.emplace_back(work, quarter * w / threads, quarter * (w + 1) / threads);
    work(0, quarter / threads);
  }
  return volume;
}

}  // namespace seqloc::pipeline
