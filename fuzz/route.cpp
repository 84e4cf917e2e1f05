// Fuzz target: the route directory reader (pipeline/route.hpp). One input carries both files:
// route.json, a line "----", then frames.csv. The frames may name v0.npy, v1.npy or o0.png,
// which exist in the scratch directory.
#include <cstdint>
#include <fstream>
#include <string>

#include "fuzz_support.hpp"
#include "seqloc/io/route.hpp"

namespace {

// A directory with the files frames may name, removed when the process ends.
const std::filesystem::path& scratch() {
  static const seqloc::fuzz::ScratchDir dir("route");
  static const bool filled = [] {
    for (const char* name : {"v0.npy", "v1.npy", "o0.png"}) std::ofstream(dir.path() / name) << "x";
    return true;
  }();
  (void)filled;
  return dir.path();
}

void write(const std::filesystem::path& path, std::string_view text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const auto [json, csv] = seqloc::fuzz::split_once(input, "\n----\n");
  const auto& dir = scratch();
  write(dir / "route.json", json);
  write(dir / "frames.csv", csv);
  try {
    const auto route = seqloc::io::read_route(dir);
    if (route.frames.empty()) std::abort();  // read_route promises at least one frame
  } catch (const seqloc::DataError&) {
  }
  return 0;
}
