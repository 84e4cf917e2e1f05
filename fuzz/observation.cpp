// Fuzz target: the BEV observation reader (pipeline/observation.hpp): PNG decoding, then the
// checks of side, pixel format and class codes.
#include <cstdint>

#include "fuzz_support.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/observation.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const seqloc::fuzz::MemoryFile file(data, size);
  try {
    const auto observation = seqloc::io::read_observation(file.path());
    if (observation.size % 2 != 1 || observation.size > seqloc::io::kMaxObservationSize ||
        observation.classes.size() != observation.cells() * 3 || observation.visible.size() != observation.cells()) {
      std::abort();  // an accepted observation keeps its documented invariants
    }
  } catch (const seqloc::DataError&) {
  }
  return 0;
}
