#include "seqloc/matcher/matcher.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/flat_index.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/osm/classes.hpp"

namespace seqloc::matcher {
namespace {

using core::kCellM;

using core::flat;

int class_count(int channel) { return static_cast<int>(osm::group_names(static_cast<osm::Channel>(channel)).size()); }

void require(bool ok, const char* field, double value, const char* rule) {
  if (ok) return;
  std::ostringstream s;
  s << "matcher: " << field << " = " << value << ": " << rule;
  throw UsageError(s.str());
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

/// The observation's indicator of one code in the body frame, visible cells only, limited to the
/// inscribed disc so that no rotation clips it. A negative channel takes every visible cell of the
/// disc: the sum of any one channel's code indicators.
std::vector<float> body_indicator(const io::Observation& observation, int channel, int code) {
  const int t = observation.size;
  const double centre = (t - 1) / 2.0;
  std::vector<float> body(observation.cells(), 0.0f);
  for (int r = 0; r < t; ++r) {
    for (int c = 0; c < t; ++c) {
      const auto i = flat(r, c, t);
      const double dr = r - centre, dc = c - centre;
      if (observation.visible[i] &&
          (channel < 0 || observation.classes[3 * i + static_cast<std::size_t>(channel)] == code) &&
          dr * dr + dc * dc <= centre * centre + 1e-9) {
        body[i] = 1.0f;
      }
    }
  }
  return body;
}

/// Each body turned to grid heading `heading_deg` (clockwise) about the camera and sampled
/// bilinearly, north-up: the sampling is worked out once per cell for all of them.
void rotate_bodies(const std::vector<std::vector<float>>& bodies, int t, double heading_deg,
                   std::vector<std::vector<float>>& out) {
  const double centre = (t - 1) / 2.0;
  const auto cells = static_cast<std::size_t>(t) * static_cast<std::size_t>(t);
  out.resize(bodies.size());
  for (auto& o : out) o.assign(cells, 0.0f);
  const double th = heading_deg * core::kDegToRad, s = std::sin(th), c = std::cos(th);
  for (int row = 0; row < t; ++row) {
    for (int col = 0; col < t; ++col) {
      // North-up cell (east e, north n from the camera) -> body (forward f, right r).
      const double e = col - centre, n = centre - row;
      const double f = e * s + n * c, rt = e * c - n * s;
      const double br = centre - f, bc = centre + rt;
      const double r0 = std::floor(br), c0 = std::floor(bc);
      const double wr = br - r0, wc = bc - c0;
      std::size_t taps[4];
      double weights[4];
      int count = 0;
      for (int dr = 0; dr < 2; ++dr) {
        for (int dc = 0; dc < 2; ++dc) {
          const int rr = static_cast<int>(r0) + dr, cc = static_cast<int>(c0) + dc;
          if (rr < 0 || rr >= t || cc < 0 || cc >= t) continue;
          taps[count] = flat(rr, cc, t);
          weights[count++] = (dr ? wr : 1 - wr) * (dc ? wc : 1 - wc);
        }
      }
      const auto i = flat(row, col, t);
      for (std::size_t b = 0; b < bodies.size(); ++b) {
        double value = 0;
        for (int k = 0; k < count; ++k) value += weights[k] * bodies[b][taps[k]];
        out[b][i] = static_cast<float>(value);
      }
    }
  }
}

// acc[q] (+)= m[q] * conj(f) for the four quarter turns q, on n x n spectra in OpenCV's CCS
// packing (n even): cv::mulSpectrums(m[q], f, ., 0, true) followed by an addition, fused so that
// f is read once for the four products and nothing is written but the sums. `assign` starts the
// sums instead of adding to them. Columns 1 .. n-2 hold (re, im) pairs; columns 0 and n-1 hold the
// transforms of the real columns packed down the rows (row 0 and row n-1 real, rows 2k-1, 2k a
// pair).
void accumulate_spectra(const cv::Mat& f, const std::array<cv::Mat, 4>& m, std::array<cv::Mat, 4>& acc, int n,
                        bool assign) {
  // The (re, im) pairs of columns 1 .. n-2, row by row: plain loops the compiler vectorizes.
  const auto pairs = [&](auto kAssign) {
    for (int i = 0; i < n; ++i) {
      const auto* __restrict fr = f.ptr<float>(i);
      for (std::size_t q = 0; q < 4; ++q) {
        const auto* __restrict mr = m[q].ptr<float>(i);
        auto* __restrict ar = acc[q].ptr<float>(i);
        for (int j = 1; j < n - 1; j += 2) {
          const float re = mr[j] * fr[j] + mr[j + 1] * fr[j + 1];
          const float im = mr[j + 1] * fr[j] - mr[j] * fr[j + 1];
          if constexpr (decltype(kAssign)::value) {
            ar[j] = re;
            ar[j + 1] = im;
          } else {
            ar[j] += re;
            ar[j + 1] += im;
          }
        }
      }
    }
  };
  if (assign) {
    pairs(std::true_type{});
  } else {
    pairs(std::false_type{});
  }
  for (const int col : {0, n - 1}) {
    for (std::size_t q = 0; q < 4; ++q) {
      auto at = [col](const cv::Mat& x, int row) -> float { return x.ptr<float>(row)[col]; };
      auto put = [&, col](int row, float value) {
        float& a = acc[q].ptr<float>(row)[col];
        a = assign ? value : a + value;
      };
      put(0, at(m[q], 0) * at(f, 0));
      put(n - 1, at(m[q], n - 1) * at(f, n - 1));
      for (int k = 1; k + 1 < n; k += 2) {
        const float mre = at(m[q], k), mim = at(m[q], k + 1), fre = at(f, k), fim = at(f, k + 1);
        put(k, mre * fre + mim * fim);
        put(k + 1, mim * fre - mre * fim);
      }
    }
  }
}

/// Writes the s x s top-left of `correlation`, turned clockwise by q quarter turns, row-major to
/// dst (what rotate_cw of that region would give, without the intermediate matrices).
void rotated_copy(const cv::Mat& correlation, int q, int s, float* dst) {
  for (int v = 0; v < s; ++v) {
    float* out = dst + static_cast<std::size_t>(v) * static_cast<std::size_t>(s);
    switch (q & 3) {
      case 0: {
        const auto* row = correlation.ptr<float>(v);
        std::copy(row, row + s, out);
        break;
      }
      case 1:  // out(v, u) = in(s - 1 - u, v)
        for (int u = 0; u < s; ++u) out[u] = correlation.ptr<float>(s - 1 - u)[v];
        break;
      case 2: {  // out(v, u) = in(s - 1 - v, s - 1 - u)
        const auto* row = correlation.ptr<float>(s - 1 - v);
        for (int u = 0; u < s; ++u) out[u] = row[s - 1 - u];
        break;
      }
      default:  // out(v, u) = in(u, s - 1 - v)
        for (int u = 0; u < s; ++u) out[u] = correlation.ptr<float>(u)[s - 1 - v];
    }
  }
}

// What every heading's scoring shares: the bodies (t x t) and the spectra of their map terms,
// turned by each quarter turn.
struct HeadingJob {
  const std::vector<std::vector<float>>& bodies;
  const std::vector<std::array<cv::Mat, 4>>& map_spectra;
  int t = 0, s = 0, n = 0, n_bins = 0;
  float scale = 1;
};

// Scores headings j0 .. j1 - 1 of the first quarter turn, and with them the same headings of the
// other three, into `volume` (s, s, n_bins). Slices go to the volume a batch of consecutive
// headings at a time, so that each cell's run of bins is written whole (one slice at a time would
// touch every cache line of the volume once per heading).
void score_headings(const HeadingJob& job, int j0, int j1, float* volume) {
  constexpr int kBatch = 16;
  const int t = job.t, s = job.s, n = job.n, quarter = job.n_bins / 4;
  const auto plane = static_cast<std::size_t>(s) * static_cast<std::size_t>(s);
  std::array<cv::Mat, 4> acc;
  for (auto& a : acc) a.create(n, n, CV_32F);
  cv::Mat correlation, template_spectrum;
  cv::Mat padded = cv::Mat::zeros(n, n, CV_32F);  // the template's t x t corner is rewritten each time
  std::vector<std::vector<float>> templates;
  std::vector<float> batch(static_cast<std::size_t>(4 * kBatch) * plane);  // [q][heading - jb][v][u]
  for (int jb = j0; jb < j1; jb += kBatch) {
    const int je = std::min(j1, jb + kBatch);
    for (int j = jb; j < je; ++j) {
      rotate_bodies(job.bodies, t, j * 360.0 / job.n_bins, templates);
      for (std::size_t o = 0; o < job.bodies.size(); ++o) {
        cv::Mat(t, t, CV_32F, templates[o].data()).copyTo(padded(cv::Rect(0, 0, t, t)));
        cv::dft(padded, template_spectrum, 0, t);
        accumulate_spectra(template_spectrum, job.map_spectra[o], acc, n, /*assign=*/o == 0);
      }
      if (job.bodies.empty()) {
        for (auto& a : acc) a.setTo(0);
      }
      // corr(R_q A, M) = R_q corr(A, R_q^-1 M): heading + q quarter turns from one template.
      // Only the first s rows of the correlation are wanted.
      for (int q = 0; q < 4; ++q) {
        cv::dft(acc[static_cast<std::size_t>(q)], correlation, cv::DFT_INVERSE | cv::DFT_REAL_OUTPUT | cv::DFT_SCALE,
                s);
        rotated_copy(correlation, q, s,
                     batch.data() + (static_cast<std::size_t>(q) * kBatch + static_cast<std::size_t>(j - jb)) * plane);
      }
    }
    const auto count = static_cast<std::size_t>(je - jb);
    for (std::size_t cell = 0; cell < plane; ++cell) {
      float* out = volume + cell * static_cast<std::size_t>(job.n_bins);
      for (std::size_t q = 0; q < 4; ++q) {
        float* run = out + flat(static_cast<int>(q), jb, quarter);  // bins jb .. je - 1 of quarter q
        const float* src = batch.data() + q * kBatch * plane + cell;
        for (std::size_t k = 0; k < count; ++k) run[k] = src[k * plane] * job.scale;
      }
    }
  }
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

std::vector<float> BevMatcher::map_term(int channel, int observed, std::span<const std::uint8_t> map_rgb,
                                        int side) const {
  const auto cells = static_cast<std::size_t>(side) * static_cast<std::size_t>(side);
  if (map_rgb.size() != cells * 3) throw UsageError("matcher: the map crop's size does not match its side");
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
    for (std::size_t i = 0; i < cells; ++i)
      ind[i] = map_rgb[3 * i + static_cast<std::size_t>(channel)] == m ? 1.0f : 0.0f;
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

std::vector<float> BevMatcher::rotated_template(const io::Observation& observation, int channel, int code,
                                                double heading_deg) const {
  const std::vector<std::vector<float>> bodies{body_indicator(observation, channel, code)};
  std::vector<std::vector<float>> out;
  rotate_bodies(bodies, observation.size, heading_deg, out);
  return std::move(out[0]);
}

std::vector<std::array<int, 2>> BevMatcher::observed_codes(const io::Observation& observation) {
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

// The score of a pose sums, over the observed codes o, the map term s(o, .) under the rotated
// indicator T_o. The indicators of one channel's codes partition the visible disc V, so with one
// reference code r(c) per channel, sum_o T_o s(o) = V * sum_c s(r(c)) + sum_{o != r} T_o (s(o) -
// s(r(c))): a frame costs one template for V plus one per code beyond the first of each channel
// (about 3 instead of 5 on rural frames); the same sum, up to float rounding.
std::pair<std::vector<std::vector<float>>, std::vector<std::vector<float>>> BevMatcher::correlands(
    const io::Observation& observation, std::span<const std::uint8_t> map_rgb, int side) const {
  const auto codes = observed_codes(observation);
  std::vector<std::vector<float>> bodies;  // [0]: V; then the non-reference codes
  std::vector<std::vector<float>> terms;   // the map term each body is correlated with
  bodies.reserve(codes.size() + 1);
  terms.reserve(codes.size() + 1);
  std::vector<float> reference;  // the map term of the current channel's reference code
  for (std::size_t o = 0; o < codes.size(); ++o) {
    const auto [channel, code] = codes[o];
    auto term = map_term(channel, code, map_rgb, side);
    if (o == 0 || codes[o - 1][0] != channel) {  // codes come sorted by channel: its first is the reference
      if (terms.empty()) {
        bodies.push_back(body_indicator(observation, -1, 0));
        terms.push_back(term);
      } else {
        std::transform(terms[0].begin(), terms[0].end(), term.begin(), terms[0].begin(), std::plus<>());
      }
      reference = std::move(term);
      continue;
    }
    std::transform(term.begin(), term.end(), reference.begin(), term.begin(), std::minus<>());
    bodies.push_back(body_indicator(observation, channel, code));
    terms.push_back(std::move(term));
  }
  return {std::move(bodies), std::move(terms)};
}

std::vector<float> BevMatcher::match(const io::Observation& observation, std::span<const std::uint8_t> map_rgb) const {
  const int t = observation.size, s = config_.size, n_bins = config_.headings;
  const int side = map_side(t);
  if (t < 1 || t % 2 == 0 || observation.classes.size() != observation.cells() * 3 ||
      observation.visible.size() != observation.cells()) {
    throw UsageError("matcher: the observation must be square with an odd side");
  }
  if (map_rgb.size() != static_cast<std::size_t>(side) * static_cast<std::size_t>(side) * 3) {
    std::ostringstream m;
    m << "matcher: the map crop must be " << side << " x " << side << " cells for an observation of side " << t;
    throw UsageError(m.str());
  }
  // An even transform size: accumulate_spectra reads the CCS packing of even sizes.
  int n = cv::getOptimalDFTSize(side);
  while (n % 2) n = cv::getOptimalDFTSize(n + 1);
  auto [bodies, terms] = correlands(observation, map_rgb, side);
  // Each map term, turned counter-clockwise by q quarter turns, transformed.
  std::vector<std::array<cv::Mat, 4>> map_spectra(terms.size());
  for (std::size_t o = 0; o < terms.size(); ++o) {
    const cv::Mat m(side, side, CV_32F, terms[o].data());
    for (int q = 0; q < 4; ++q) map_spectra[o][static_cast<std::size_t>(q)] = spectrum(rotate_cw(m, -q), n);
  }

  std::vector<float> volume(static_cast<std::size_t>(s) * static_cast<std::size_t>(s) *
                            static_cast<std::size_t>(n_bins));
  const HeadingJob job{bodies, map_spectra, t, s, n, n_bins, static_cast<float>(1.0 / config_.temperature)};
  const int quarter = n_bins / 4;
  // A quarter of the headings, shared among the threads (the other three quarters are rotations).
  core::parallel_chunks(quarter, config_.threads,
                        [&](int begin, int end, int) { score_headings(job, begin, end, volume.data()); });
  return volume;
}

}  // namespace seqloc::matcher
