#pragma once
// The filter's buffers are the intake's (intake/aligned.hpp): cache-line aligned, so that every
// run splits its vectorized loops the same way.

#include "seqloc/intake/aligned.hpp"

namespace seqloc::filter {

using intake::AlignedAllocator;
using intake::AlignedVector;
using intake::kBufferAlignment;
using intake::UninitializedAlignedAllocator;
using intake::UninitializedAlignedVector;

}  // namespace seqloc::filter
