// A fixture for the layering check: the filter (Eigen only) including a pipeline header must fail.
#include "seqloc/pipeline/route.hpp"
