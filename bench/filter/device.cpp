// bench/filter --device cuda|cuda-host: one SeqLoc step of the CUDA backend (gpu::DeviceFilter)
// with the defaults, at 128x128x256 and 256x256x256 windows (sizes: --sizes), with self-
// calibration on and off, against two peers measured in the same run on the same device: a
// device-to-device copy of the belief, and one step of the plain PyTorch peer
// (bench/filter/torch_step.py, run with the Python that --python names). Prints ms/step and the
// ratios, and ends with one line of JSON.
//
// The frame is prepared on the host once (as localize's intake does, in the background) and is
// uploaded by every step: the time is the step as a localizer pays it, upload included.

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/gpu/device_filter.hpp"

namespace {

using Clock = std::chrono::steady_clock;
namespace gpu = seqloc::gpu;
namespace filter = seqloc::filter;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Row {
  int size = 0;
  bool calibrate = false;
  double step_ms = 0, copy_ms = 0, peer_ms = -1;
};

// The PyTorch peer's ms per step (its JSON line's "ms_per_step"), or -1 with the reason printed.
double torch_peer_ms(const std::string& python, const std::string& peer, int size, bool cuda) {
  const std::string command =
      python + " " + peer + " --size " + std::to_string(size) + " --device " + (cuda ? "cuda" : "cpu") + " 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command.c_str(), "r"), pclose);
  if (!pipe) return -1;
  std::string output, line;
  std::array<char, 512> buffer{};
  while (std::fgets(buffer.data(), buffer.size(), pipe.get()) != nullptr) output += buffer.data();
  const auto key = output.rfind("\"ms_per_step\": ");
  if (key == std::string::npos) {
    std::printf("PyTorch peer not measured (%s):\n%s", command.c_str(), output.c_str());
    return -1;
  }
  std::printf("%s", output.substr(0, output.find('\n') + 1).c_str());
  return std::stod(output.substr(key + 15));
}

std::vector<int> parse_sizes(const std::string& text) {
  std::vector<int> sizes;
  std::stringstream in(text);
  for (std::string part; std::getline(in, part, ',');) sizes.push_back(std::stoi(part));
  return sizes;
}

}  // namespace

int main(int argc, char** argv) {
  std::string device = "cuda", python = "python3", sizes_text = "128,256";
  std::string peer = std::string(SEQLOC_SOURCE_DIR) + "/bench/filter/torch_step.py";
  int repeats = 20;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--device" && i + 1 < argc) {
      device = argv[++i];
    } else if (a == "--python" && i + 1 < argc) {
      python = argv[++i];
    } else if (a == "--peer" && i + 1 < argc) {
      peer = argv[++i];
    } else if (a == "--sizes" && i + 1 < argc) {
      sizes_text = argv[++i];
    } else if (a == "--repeats" && i + 1 < argc) {
      repeats = std::max(3, std::stoi(argv[++i]));
    } else {
      std::fprintf(stderr,
                   "usage: bench_filter_device [--device cuda|cuda-host] [--sizes 128,256] [--repeats 20] "
                   "[--python python3] [--peer torch_step.py]\n");
      return 2;
    }
  }
  if (device != "cuda" && device != "cuda-host") {
    std::fprintf(stderr, "bench filter: --device %s: expected cuda or cuda-host\n", device.c_str());
    return 2;
  }
  const gpu::Backend backend = device == "cuda" ? gpu::Backend::cuda : gpu::Backend::host;
  const gpu::CudaStatus status = gpu::cuda_status();
  const bool runs = backend == gpu::Backend::cuda ? status.usable : gpu::built_with_cuda();
  if (!runs) {
    std::printf("bench filter --device %s: %s\n", device.c_str(), status.reason.c_str());
    std::printf("{\"benchmark\": \"filter_device\", \"device\": \"%s\", \"measured\": false, \"reason\": \"%s\"}\n",
                device.c_str(), status.reason.c_str());
    return 1;
  }
  const std::string card = backend == gpu::Backend::cuda ? status.device_name : "CPU (the host backend)";
  std::printf("device: %s\n", card.c_str());

  std::mt19937 rng(42);
  std::normal_distribution<float> noise(0, 2);
  const int vh = 128, vw = 128, vn = 256;
  std::vector<float> volume(static_cast<std::size_t>(vh) * vw * vn);
  for (auto& x : volume) x = noise(rng);
  const filter::FrameVolume view{
      volume.data(), filter::VolumeType::float32, filter::VolumeValues::log_prob, vh, vw, vn, 0.5};
  const filter::PreparedFrame frame = filter::prepare_frame(view, 256, 4);
  std::vector<Row> rows;
  for (const int size : parse_sizes(sizes_text)) {
    const double peer_ms = torch_peer_ms(python, peer, size, backend == gpu::Backend::cuda);
    for (const bool calibrate : {false, true}) {
      filter::FilterConfig c;
      c.width = c.height = size;
      c.headings = 256;
      c.self_calibrate = calibrate;
      gpu::DeviceFilter f(c, backend);
      std::vector<float> road(static_cast<std::size_t>(size) * size);
      for (int v = 0; v < size; ++v)
        for (int u = 0; u < size; ++u)
          road[static_cast<std::size_t>(v) * size + u] = static_cast<float>(std::abs(u - size / 2) * 0.5);
      std::vector<double> ms;
      for (int i = 0; i < repeats + 3; ++i) {
        const auto t0 = Clock::now();
        const auto r = f.step(frame, {size / 2.0 + (i % 3), size / 2.0 - (i % 2), 0}, {3.7, 0.2, 4.3}, road);
        if (i >= 3) ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        if (r.pose.u < -1e9) std::puts("");  // keep the result alive
      }
      const std::size_t bytes = static_cast<std::size_t>(size) * size * 256 * sizeof(float);
      Row row{size, calibrate, median(ms), gpu::copy_ms(backend, bytes, repeats), peer_ms};
      rows.push_back(row);
      std::printf(
          "%dx%dx256, self-calibration %s: %.3f ms/step (%.0f frames/s); copy of the belief (%.0f MB) %.4f ms, "
          "step / copy = %.1f",
          size, size, calibrate ? "on " : "off", row.step_ms, 1000.0 / row.step_ms, static_cast<double>(bytes) / 1e6,
          row.copy_ms, row.step_ms / row.copy_ms);
      if (peer_ms > 0) std::printf("; PyTorch peer %.3f ms, peer / step = %.1fx", peer_ms, peer_ms / row.step_ms);
      std::printf("\n");
    }
  }
  std::string json = "{\"benchmark\": \"filter_device\", \"device\": \"" + device + "\", \"card\": \"" + card +
                     "\", \"measured\": true, \"volume\": \"128x128x256 float32\", \"rows\": [";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    std::array<char, 320> buffer{};
    std::snprintf(buffer.data(), buffer.size(),
                  "%s{\"window\": %d, \"self_calibrate\": %s, \"ms_per_step\": %.4f, \"copy_ms\": %.4f, "
                  "\"step_over_copy\": %.2f, \"pytorch_ms\": %.4f, \"pytorch_over_step\": %.2f}",
                  i ? ", " : "", rows[i].size, rows[i].calibrate ? "true" : "false", rows[i].step_ms, rows[i].copy_ms,
                  rows[i].step_ms / rows[i].copy_ms, rows[i].peer_ms,
                  rows[i].peer_ms > 0 ? rows[i].peer_ms / rows[i].step_ms : -1.0);
    json += buffer.data();
  }
  std::printf("%s]}\n", json.c_str());
  return 0;
}
