// Fuzz target: the .npy volume reader (io/npy.hpp), then a read of every value it maps,
// so a shape check that lets the data run past the mapping is caught by ASan.
#include <cstdint>
#include <cstring>

#include "fuzz_support.hpp"
#include "seqloc/io/npy.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const seqloc::fuzz::MemoryFile file(data, size);
  try {
    const seqloc::io::NpyVolume volume(file.path());
    const std::size_t cells = static_cast<std::size_t>(volume.height()) * static_cast<std::size_t>(volume.width()) *
                              static_cast<std::size_t>(volume.bins());
    const std::size_t bytes = cells * (volume.type() == seqloc::core::VolumeType::float32 ? 4 : 2);
    const auto* p = static_cast<const unsigned char*>(volume.data());
    unsigned sum = 0;
    for (std::size_t i = 0; i < bytes; ++i) sum += p[i];
    volatile unsigned sink = sum;
    (void)sink;
  } catch (const seqloc::DataError&) {
  }
  return 0;
}
