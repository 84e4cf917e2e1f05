// DeviceFilter's engine in a build without CUDA (nvcc was not found at configure time): every
// backend refuses, naming why. The host backend runs the CUDA kernels' code, which only nvcc
// compiles.

#include <string>

#include "engine.hpp"

namespace seqloc::gpu {

namespace {
constexpr const char* kNoCuda = "this seqloc was built without CUDA (nvcc was not found when it was configured)";
}

bool built_with_cuda() { return false; }

CudaStatus cuda_status() {
  CudaStatus status;
  status.reason = kNoCuda;
  return status;
}

double copy_ms(Backend, std::size_t, int) {
  throw filter::FilterError(std::string("the CUDA backend cannot run: ") + kNoCuda, ErrorCategory::io);
}

std::unique_ptr<DeviceFilter::Engine> make_engine(const filter::FilterConfig&, Backend) {
  throw filter::FilterError(std::string("the CUDA backend cannot run: ") + kNoCuda, ErrorCategory::io);
}

}  // namespace seqloc::gpu
