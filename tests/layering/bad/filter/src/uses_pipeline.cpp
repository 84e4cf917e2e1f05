// A fixture for the layering check: the filter (core and Eigen only) including a pipeline header must fail.
#include "seqloc/pipeline/localize.hpp"
