// DeviceFilter's kernels over an execution space: Thrust's CUDA system for the GPU, its host
// system (the same functors, one element at a time) for the tests. Each kernel is a functor whose
// per-cell arithmetic comes from filter/device_math.hpp.

#include <cuda_runtime.h>
#include <thrust/execution_policy.h>
#include <thrust/extrema.h>
#include <thrust/for_each.h>
#include <thrust/functional.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/pair.h>
#include <thrust/reduce.h>
#include <thrust/transform_reduce.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <new>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "engine.hpp"
#include "seqloc/filter/calibration_evidence.hpp"

namespace seqloc::gpu {
namespace {

using filter::FilterError;
using filter::math::Translation;

[[noreturn]] void cuda_failure(const char* what, cudaError_t error) {
  const auto category = error == cudaErrorMemoryAllocation ? ErrorCategory::io : ErrorCategory::internal;
  throw FilterError(std::string("CUDA: ") + what + " failed: " + cudaGetErrorString(error), category);
}

void check(cudaError_t error, const char* what) {
  if (error != cudaSuccess) cuda_failure(what, error);
}

// ---------------------------------------------------------------------------------------------
// Execution spaces: where buffers live, how bytes cross, which Thrust system runs the kernels.

struct HostSpace {
  static auto policy() { return thrust::host; }
  static void* allocate(std::size_t bytes) { return ::operator new(bytes); }
  static void release(void* p) { ::operator delete(p); }
  static void upload(void* dst, const void* src, std::size_t bytes) { std::memcpy(dst, src, bytes); }
  static void download(void* dst, const void* src, std::size_t bytes) { std::memcpy(dst, src, bytes); }
  static void copy(void* dst, const void* src, std::size_t bytes) { std::memcpy(dst, src, bytes); }
};

struct CudaSpace {
  static auto policy() { return thrust::device; }
  static void* allocate(std::size_t bytes) {
    void* p = nullptr;
    const cudaError_t error = cudaMalloc(&p, bytes);
    if (error != cudaSuccess) {
      throw FilterError(
          "CUDA: cannot allocate " + std::to_string(bytes >> 20) + " MiB on the device: " + cudaGetErrorString(error),
          ErrorCategory::io);
    }
    return p;
  }
  static void release(void* p) { cudaFree(p); }
  static void upload(void* dst, const void* src, std::size_t bytes) {
    check(cudaMemcpy(dst, src, bytes, cudaMemcpyHostToDevice), "copy to the device");
  }
  static void download(void* dst, const void* src, std::size_t bytes) {
    check(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToHost), "copy from the device");
  }
  static void copy(void* dst, const void* src, std::size_t bytes) {
    check(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToDevice), "copy on the device");
  }
};

/// An array in a space's memory; grows, never shrinks.
template <class T, class Space>
class Buffer {
 public:
  Buffer() = default;
  explicit Buffer(std::size_t n) { resize(n); }
  ~Buffer() {
    if (data_ != nullptr) Space::release(data_);
  }
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  void resize(std::size_t n) {
    if (n <= capacity_) {
      size_ = n;
      return;
    }
    T* fresh = static_cast<T*>(Space::allocate(n * sizeof(T)));
    if (data_ != nullptr) Space::release(data_);
    data_ = fresh;
    size_ = capacity_ = n;
  }
  void upload(const T* host, std::size_t n) {
    resize(n);
    if (n > 0) Space::upload(data_, host, n * sizeof(T));
  }
  void download(T* host, std::size_t n, std::size_t offset = 0) const {
    if (n > 0) Space::download(host, data_ + offset, n * sizeof(T));
  }
  void swap(Buffer& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(size_, other.size_);
    std::swap(capacity_, other.capacity_);
  }
  [[nodiscard]] T* data() { return data_; }
  [[nodiscard]] const T* data() const { return data_; }
  [[nodiscard]] std::size_t size() const { return size_; }

 private:
  T* data_ = nullptr;
  std::size_t size_ = 0, capacity_ = 0;
};

// ---------------------------------------------------------------------------------------------
// The kernels, as functors of a flat index.

struct Reader {
  const float* p;
  SEQLOC_HD float operator()(std::size_t i) const { return p[i]; }
};

/// The frame's two heading bins blended as the window bin reads them.
struct BlendReader {
  const float* s0;
  const float* s1;
  float a;
  SEQLOC_HD float operator()(std::size_t i) const { return a > 0 ? (1 - a) * s0[i] + a * s1[i] : s0[i]; }
};

struct Cell {
  int u, v, k;
  std::size_t c;  ///< within the slice
};

SEQLOC_HD inline Cell cell_of(std::size_t i, int width, std::size_t slice) {
  const auto c = i % slice;
  return {static_cast<int>(c % width), static_cast<int>(c / width), static_cast<int>(i / slice), c};
}

struct PredictKernel {
  const float* src;
  float* dst;
  const Translation* by_bin;
  int width, headings, s;
  std::size_t slice;
  float a, fill;
  SEQLOC_HD void operator()(std::size_t i) const {
    const Cell at = cell_of(i, width, slice);
    const int j0 = (at.k + s) % headings;
    const float v0 = filter::math::translate_at(by_bin[j0], at.u, at.v, fill, Reader{src + j0 * slice});
    if (a == 0.0f) {
      dst[i] = v0;
      return;
    }
    const int j1 = (at.k + s + 1) % headings;
    const float v1 = filter::math::translate_at(by_bin[j1], at.u, at.v, fill, Reader{src + j1 * slice});
    dst[i] = (1 - a) * v0 + a * v1;
  }
};

struct RecentreKernel {
  const float* src;
  float* dst;
  int width, height, du, dv;
  std::size_t slice;
  float fill;
  SEQLOC_HD void operator()(std::size_t i) const {
    const Cell at = cell_of(i, width, slice);
    const int su = at.u + du, sv = at.v + dv;
    dst[i] = su >= 0 && su < width && sv >= 0 && sv < height
                 ? src[at.k * slice + static_cast<std::size_t>(sv) * width + su]
                 : fill;
  }
};

struct PowKernel {
  float* b;
  float ratio;
  SEQLOC_HD void operator()(std::size_t i) const { b[i] = ::powf(b[i], ratio); }
};

struct ScaleKernel {
  float* b;
  const float* add;  ///< per slice cell, or null
  float keep;
  std::size_t slice;
  SEQLOC_HD void operator()(std::size_t i) const { b[i] = add != nullptr ? b[i] * keep + add[i % slice] : b[i] * keep; }
};

struct TemperKernel {
  const float* frame;
  float* out;
  float exponent, peak;
  SEQLOC_HD void operator()(std::size_t i) const { out[i] = filter::math::exp_or_zero(frame[i], exponent, peak); }
};

struct FrameSumsOp {
  const float* frame;
  float power, peak;
  SEQLOC_HD thrust::pair<double, double> operator()(std::size_t i) const {
    const float x = frame[i];
    const float r = (x > filter::math::kLogZeroValue ? x : filter::math::kLogZeroValue) - peak;
    const float e = filter::math::exp_or_zero(x, power, peak);
    return {static_cast<double>(e), static_cast<double>(e * r)};
  }
};

struct PairPlus {
  SEQLOC_HD thrust::pair<double, double> operator()(const thrust::pair<double, double>& a,
                                                    const thrust::pair<double, double>& b) const {
    return {a.first + b.first, a.second + b.second};
  }
};

struct ToDouble {
  SEQLOC_HD double operator()(float x) const { return static_cast<double>(x); }
};

struct PoolKernel {
  const float* belief;
  float* coarse;
  int width, height, headings, coarse_width, per_coarse_bin;
  std::size_t slice, coarse_slice;
  SEQLOC_HD void operator()(std::size_t i) const {
    const Cell at = cell_of(i, coarse_width, coarse_slice);
    const int b = per_coarse_bin, half = b / 2;
    float sum = 0;
    for (int d = -half; d <= half; ++d) {
      const int k = ((b * at.k + d) % headings + headings) % headings;
      if (!filter::math::pooled_bin(k, b)) continue;
      sum += filter::math::pooled_weight(d, b) * filter::math::pool_2x2(belief + k * slice, width, height, at.u, at.v);
    }
    coarse[i] = sum;
  }
};

// Adds to a sum that many cells add to: atomically on the GPU; the host system runs a kernel one
// element at a time.
SEQLOC_HD inline void add_to(unsigned long long* sum, unsigned long long x) {
#if defined(__CUDA_ARCH__)
  atomicAdd(sum, x);
#else
  *sum += x;
#endif
}

SEQLOC_HD inline void add_to(double* sum, double x) {
#if defined(__CUDA_ARCH__)
  atomicAdd(sum, x);
#else
  *sum += x;
#endif
}

/// DepthHistogram sums in the space's memory: weights then depth sums, `bins` each.
struct HistogramView {
  unsigned long long* weight;
  unsigned long long* depth;
  SEQLOC_HD void add(const filter::math::DepthTerm& t) const {
    add_to(weight + t.bin, static_cast<unsigned long long>(t.weight));
    add_to(depth + t.bin, static_cast<unsigned long long>(t.depth_sum));
  }
};

// The frame's own cells by depth (filter::add_frame_cells): every stride-th bin, each cell
// counting for `stride` cells.
struct FrameCellsKernel {
  const float* frame;
  HistogramView cells;
  std::size_t slice;
  int stride, last_bin;
  float peak, max_depth, per_nat;
  filter::DepthHistogram::Scale scale;
  SEQLOC_HD void operator()(std::size_t i) const {
    const std::size_t j = i / slice * static_cast<std::size_t>(stride);
    const float x = frame[j * slice + i % slice];
    if (!(x > filter::math::kLogZeroValue)) return;
    const float r = x - peak;  // x > log(0): max(x, log(0)) is x
    cells.add(filter::math::depth_term(r, static_cast<float>(stride), max_depth, per_nat, last_bin, scale.weight,
                                       scale.depth));
  }
};

// The pooled belief judged by the frame (filter/calibration_evidence.cpp's judge_frame): each
// coarse cell's mass by the frame's depth there, or outside the crop.
struct JudgeKernel {
  const float* frame;
  const float* coarse;
  const HeadingBlend* blend;
  CropGeometry geometry;
  HistogramView mass;
  double* outside_mass;
  unsigned long long* outside_cells;
  int coarse_width, last_bin;
  std::size_t coarse_slice, frame_slice;
  float peak, max_depth, per_nat;
  filter::DepthHistogram::Scale scale;
  SEQLOC_HD void operator()(std::size_t i) const {
    constexpr float kOutside = 1.0f;  // no log-probability is positive
    const Cell at = cell_of(i, coarse_width, coarse_slice);
    const HeadingBlend hb = blend[at.k];
    const BlendReader read{frame + hb.j0 * frame_slice, frame + hb.j1 * frame_slice, hb.a};
    const float x = geometry.translate ? filter::math::translate_at(geometry.translation, at.u, at.v, kOutside, read)
                                       : filter::math::crop_sample_at(geometry.map, at.u, at.v, kOutside, read);
    const float m = coarse[i];
    if (!(x <= 0.5f)) {
      add_to(outside_mass, static_cast<double>(m));
      add_to(outside_cells, 1ull);
      return;
    }
    if (!(m >= 1e-12f)) return;
    const float r = (x > filter::math::kLogZeroValue ? x : filter::math::kLogZeroValue) - peak;
    mass.add(filter::math::depth_term(r, m, max_depth, per_nat, last_bin, scale.weight, scale.depth));
  }
};

struct MultiplyKernel {
  float* belief;
  const float* tempered;
  const HeadingBlend* blend;
  const float* gps;  ///< per slice cell, or null
  CropGeometry geometry;
  int width;
  std::size_t slice, frame_slice;
  float outside;
  bool with_prior;
  SEQLOC_HD void operator()(std::size_t i) const {
    const Cell at = cell_of(i, width, slice);
    const HeadingBlend hb = blend[at.k];
    const BlendReader read{tempered + hb.j0 * frame_slice, tempered + hb.j1 * frame_slice, hb.a};
    const float sample = geometry.translate
                             ? filter::math::translate_at(geometry.translation, at.u, at.v, outside, read)
                             : filter::math::crop_sample_at(geometry.map, at.u, at.v, outside, read);
    float b = with_prior ? belief[i] * sample : sample;
    if (gps != nullptr) b *= gps[at.c];
    belief[i] = b;
  }
};

struct RoadPriorGKernel {
  const float* distance;
  double* g;
  double sigma;
  SEQLOC_HD void operator()(std::size_t i) const { g[i] = filter::math::road_prior_g(distance[i], sigma); }
};

struct RoadPriorShareKernel {
  const double* g;
  float* share;
  double z, n;
  int headings;
  float eps;
  SEQLOC_HD void operator()(std::size_t i) const {
    share[i] = filter::math::road_prior_share(g[i], z, n, headings, eps);
  }
};

struct PositionMassKernel {
  const float* belief;
  double* out;
  int width, u0, v0, region_width, headings;
  std::size_t slice;
  SEQLOC_HD void operator()(std::size_t i) const {
    const int u = u0 + static_cast<int>(i % region_width), v = v0 + static_cast<int>(i / region_width);
    double sum = 0;
    for (int k = 0; k < headings; ++k) sum += belief[k * slice + static_cast<std::size_t>(v) * width + u];
    out[i] = sum;
  }
};

// ---------------------------------------------------------------------------------------------

template <class Space>
class ThrustEngine final : public DeviceFilter::Engine {
 public:
  explicit ThrustEngine(const filter::FilterConfig& c)
      : width_(c.width),
        height_(c.height),
        headings_(c.headings),
        slice_(static_cast<std::size_t>(c.width) * c.height),
        cells_(slice_ * static_cast<std::size_t>(c.headings)),
        belief_(cells_),
        scratch_(cells_),
        by_bin_(static_cast<std::size_t>(c.headings)),
        blend_(static_cast<std::size_t>(c.headings)) {
    if (c.self_calibrate) {
      const filter::BeliefVolume shape = filter::coarse_belief_for(c);
      coarse_width_ = shape.width();
      coarse_height_ = shape.height();
      coarse_headings_ = shape.headings();
      coarse_.resize(shape.size());
    }
  }

  void upload_belief(const float* host) override { belief_.upload(host, cells_); }
  void download_belief(float* host) const override { belief_.download(host, cells_); }
  void fill_belief(float value) override {
    std::vector<float> host(cells_, value);
    belief_.upload(host.data(), cells_);
  }
  [[nodiscard]] float least() const override {
    const float* p = belief_.data();
    const auto at = thrust::min_element(Space::policy(), p, p + cells_) - p;
    float value = 0;
    belief_.download(&value, 1, static_cast<std::size_t>(at));
    return value;
  }

  void predict(std::span<const Translation> by_bin, int s, float a, float fill) override {
    by_bin_.upload(by_bin.data(), by_bin.size());
    run(PredictKernel{belief_.data(), scratch_.data(), by_bin_.data(), width_, headings_, s, slice_, a, fill});
    belief_.swap(scratch_);
  }

  void recentre(int du, int dv) override {
    if (du == 0 && dv == 0) return;
    const float fill = least();
    run(RecentreKernel{belief_.data(), scratch_.data(), width_, height_, du, dv, slice_, fill});
    belief_.swap(scratch_);
  }

  bool raise(float ratio) override {
    Space::copy(scratch_.data(), belief_.data(), cells_ * sizeof(float));
    run(PowKernel{belief_.data(), ratio});
    const double total = sum();
    if (!(total > 0) || !std::isfinite(total)) {
      belief_.swap(scratch_);
      return false;
    }
    run(ScaleKernel{belief_.data(), nullptr, static_cast<float>(1 / total), slice_});
    return true;
  }

  void load_frame(const filter::PreparedFrame& frame) override {
    frame_slice_ = static_cast<std::size_t>(frame.width) * frame.height;
    frame_bins_ = frame.bins;
    frame_.upload(frame.log_prob.data(), frame.log_prob.size());
    tempered_.resize(frame.log_prob.size());
  }

  [[nodiscard]] FrameSums frame_sums(float power, float peak) const override {
    const auto sums = thrust::transform_reduce(Space::policy(), thrust::counting_iterator<std::size_t>(0),
                                               thrust::counting_iterator<std::size_t>(frame_.size()),
                                               FrameSumsOp{frame_.data(), power, peak},
                                               thrust::pair<double, double>(0.0, 0.0), PairPlus{});
    return {sums.first, sums.second};
  }

  void temper(float exponent, float peak) override {
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), frame_.size(),
                       TemperKernel{frame_.data(), tempered_.data(), exponent, peak});
  }

  void pool_coarse() override {
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), coarse_cells(),
                       PoolKernel{belief_.data(), coarse_.data(), width_, height_, headings_, coarse_width_,
                                  headings_ / coarse_headings_, slice_, coarse_slice()});
  }

  void download_coarse(filter::BeliefVolume& coarse) const override { coarse_.download(coarse.data(), coarse.size()); }

  [[nodiscard]] JudgeSums judge(const JudgeSetup& setup) override {
    const std::size_t bins = filter::DepthHistogram::bins();
    std::vector<unsigned long long> zeros(4 * bins + 1, 0);
    sums_.upload(zeros.data(), zeros.size());  // four histograms and the outside cells' count
    outside_.upload(std::vector<double>{0.0}.data(), 1);
    const HistogramView frame_cells{sums_.data(), sums_.data() + bins},
        mass{sums_.data() + 2 * bins, sums_.data() + 3 * bins};
    const std::size_t binned = (static_cast<std::size_t>(frame_bins_) + setup.frame_stride - 1) / setup.frame_stride;
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), binned * frame_slice_,
                       FrameCellsKernel{frame_.data(), frame_cells, frame_slice_, setup.frame_stride, setup.last_bin,
                                        setup.peak, setup.max_depth, setup.per_nat, setup.count_scale});
    blend_.upload(setup.blend.data(), setup.blend.size());
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), coarse_cells(),
                       JudgeKernel{frame_.data(), coarse_.data(), blend_.data(), setup.geometry, mass, outside_.data(),
                                   sums_.data() + 4 * bins, coarse_width_, setup.last_bin, coarse_slice(), frame_slice_,
                                   setup.peak, setup.max_depth, setup.per_nat, setup.mass_scale});
    std::vector<unsigned long long> host(zeros.size());
    sums_.download(host.data(), host.size());
    JudgeSums out;
    auto part = [&](std::size_t k) {
      return std::vector<std::int64_t>(host.begin() + static_cast<std::ptrdiff_t>(k * bins),
                                       host.begin() + static_cast<std::ptrdiff_t>((k + 1) * bins));
    };
    out.frame_weight = part(0);
    out.frame_depth = part(1);
    out.mass_weight = part(2);
    out.mass_depth = part(3);
    out.outside_cells = host.back();
    outside_.download(&out.outside_mass, 1);
    return out;
  }

  double multiply(std::span<const HeadingBlend> blend, const CropGeometry& geometry, float outside,
                  std::span<const float> gps_factor, bool with_prior) override {
    blend_.upload(blend.data(), blend.size());
    const float* gps = nullptr;
    if (!gps_factor.empty()) {
      gps_.upload(gps_factor.data(), gps_factor.size());
      gps = gps_.data();
    }
    run(MultiplyKernel{belief_.data(), tempered_.data(), blend_.data(), gps, geometry, width_, slice_, frame_slice_,
                       outside, with_prior});
    return sum();
  }

  void set_road_prior(std::span<const float> distance_m, double sigma_m, float eps) override {
    distance_.upload(distance_m.data(), distance_m.size());
    road_g_.resize(slice_);
    add_.resize(slice_);
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), slice_,
                       RoadPriorGKernel{distance_.data(), road_g_.data(), sigma_m});
    const double* g = road_g_.data();
    const double z = thrust::reduce(Space::policy(), g, g + slice_, 0.0, thrust::plus<double>());
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), slice_,
                       RoadPriorShareKernel{g, add_.data(), z, static_cast<double>(slice_), headings_, eps});
  }

  PeakCell normalize(float keep, bool mgr) override {
    const float* plus = mgr ? add_.data() : nullptr;
    run(ScaleKernel{belief_.data(), plus, keep, slice_});
    const float* p = belief_.data();
    const auto best = static_cast<std::size_t>(thrust::max_element(Space::policy(), p, p + cells_) - p);
    PeakCell peak;
    belief_.download(&peak.value, 1, best);
    peak.least = least();
    const Cell at = cell_of(best, width_, slice_);
    peak.u = at.u;
    peak.v = at.v;
    peak.k = at.k;
    return peak;
  }

  void position_masses(int u0, int v0, int u1, int v1, std::span<double> out) const override {
    const auto n = static_cast<std::size_t>(u1 - u0 + 1) * static_cast<std::size_t>(v1 - v0 + 1);
    masses_.resize(n);
    thrust::for_each_n(
        Space::policy(), thrust::counting_iterator<std::size_t>(0), n,
        PositionMassKernel{belief_.data(), masses_.data(), width_, u0, v0, u1 - u0 + 1, headings_, slice_});
    masses_.download(out.data(), n);
  }

  [[nodiscard]] float value(int u, int v, int k) const override {
    float x = 0;
    belief_.download(&x, 1, static_cast<std::size_t>(k) * slice_ + static_cast<std::size_t>(v) * width_ + u);
    return x;
  }

 private:
  template <class Kernel>
  void run(const Kernel& kernel) {
    thrust::for_each_n(Space::policy(), thrust::counting_iterator<std::size_t>(0), cells_, kernel);
  }
  [[nodiscard]] std::size_t coarse_slice() const {
    return static_cast<std::size_t>(coarse_width_) * static_cast<std::size_t>(coarse_height_);
  }
  [[nodiscard]] std::size_t coarse_cells() const { return coarse_slice() * static_cast<std::size_t>(coarse_headings_); }
  [[nodiscard]] double sum() const {
    const float* p = belief_.data();
    return thrust::transform_reduce(Space::policy(), p, p + cells_, ToDouble{}, 0.0, thrust::plus<double>());
  }

  int width_, height_, headings_;
  int coarse_width_ = 0, coarse_height_ = 0, coarse_headings_ = 1, frame_bins_ = 0;
  std::size_t slice_, cells_, frame_slice_ = 0;
  Buffer<float, Space> belief_, scratch_, frame_, tempered_, gps_, add_, distance_;
  Buffer<double, Space> road_g_;
  Buffer<float, Space> coarse_;
  Buffer<unsigned long long, Space> sums_;
  Buffer<double, Space> outside_;
  mutable Buffer<double, Space> masses_;
  Buffer<Translation, Space> by_bin_;
  Buffer<HeadingBlend, Space> blend_;
};

CudaStatus probe_cuda() {
  CudaStatus status;
  int driver = 0, runtime = 0;
  cudaRuntimeGetVersion(&runtime);
  if (cudaDriverGetVersion(&driver) != cudaSuccess || driver == 0) {
    status.reason = "no CUDA driver is installed (this machine has no usable NVIDIA GPU)";
    return status;
  }
  int count = 0;
  const cudaError_t error = cudaGetDeviceCount(&count);
  if (error == cudaErrorInsufficientDriver) {
    status.reason = "the CUDA driver (" + std::to_string(driver / 1000) + "." + std::to_string(driver % 1000 / 10) +
                    ") is older than this build's CUDA runtime (" + std::to_string(runtime / 1000) + "." +
                    std::to_string(runtime % 1000 / 10) + ")";
    return status;
  }
  if (error != cudaSuccess || count == 0) {
    status.reason = std::string("no CUDA device: ") + (error != cudaSuccess ? cudaGetErrorString(error) : "none found");
    return status;
  }
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) {
    status.reason = "CUDA device 0 cannot be queried";
    return status;
  }
  status.usable = true;
  status.device_name = prop.name;
  status.compute_capability = prop.major * 10 + prop.minor;
  status.memory_bytes = prop.totalGlobalMem;
  return status;
}

template <class Space>
double time_copies(std::size_t bytes, int repeats) {
  Buffer<unsigned char, Space> a(bytes), b(bytes);
  Space::copy(a.data(), b.data(), bytes);  // first touch
  if constexpr (std::is_same_v<Space, CudaSpace>) check(cudaDeviceSynchronize(), "synchronize");
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    Space::copy(a.data(), b.data(), bytes);
    if constexpr (std::is_same_v<Space, CudaSpace>) check(cudaDeviceSynchronize(), "synchronize");
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

}  // namespace

bool built_with_cuda() { return true; }

double copy_ms(Backend backend, std::size_t bytes, int repeats) {
  if (repeats < 1) throw FilterError("copy_ms: repeats must be >= 1", ErrorCategory::usage);
  if (backend == Backend::host) return time_copies<HostSpace>(bytes, repeats);
  const CudaStatus status = cuda_status();
  if (!status.usable) throw FilterError("the CUDA backend cannot run: " + status.reason, ErrorCategory::io);
  return time_copies<CudaSpace>(bytes, repeats);
}

CudaStatus cuda_status() {
  static const CudaStatus status = probe_cuda();
  return status;
}

std::unique_ptr<DeviceFilter::Engine> make_engine(const filter::FilterConfig& config, Backend backend) {
  if (backend == Backend::host) return std::make_unique<ThrustEngine<HostSpace>>(config);
  const CudaStatus status = cuda_status();
  if (!status.usable) throw FilterError("the CUDA backend cannot run: " + status.reason, ErrorCategory::io);
  return std::make_unique<ThrustEngine<CudaSpace>>(config);
}

}  // namespace seqloc::gpu
