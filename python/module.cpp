// seqloc._seqloc, the compiled part of the `seqloc` Python package (docs/python.md): region
// caches, route and run folders, the SeqLoc filter and localize's localizer for Python tools, e.g.
// a PyTorch loop that feeds a backbone the map crop around a GPS fix and runs SeqLoc online on its
// output. Results are typed objects (python/seqloc/_seqloc.pyi lists them); arrays come back as
// NumPy arrays that own the C++ buffers (no copies); volumes go in as arrays read in place.
//
// Each concern is bound in a file of its own (bindings.hpp lists them); this one is the module.

#include "bindings.hpp"

namespace py = pybind11;
namespace bindings = seqloc::python;

PYBIND11_MODULE(_seqloc, m) {
  m.doc() = "seqloc's compiled part: region caches, route and run folders, the SeqLoc filter and localizer";
  m.attr("__version__") = SEQLOC_VERSION;
  bindings::register_errors(m);
  bindings::bind_map_results(m);
  bindings::bind_filter_results(m);
  bindings::bind_poses(m);
  bindings::bind_routes(m);
  bindings::bind_run_folder(m);
  bindings::bind_cache(m);
  bindings::bind_filter(m);
  bindings::bind_localizer(m);
  m.def(
      "cuda_status",
      [] {
        const seqloc::gpu::CudaStatus s = seqloc::gpu::cuda_status();
        py::dict d;
        d["built"] = seqloc::gpu::built_with_cuda();
        d["usable"] = s.usable;
        d["reason"] = s.reason;
        d["device"] = s.device_name;
        return d;
      },
      "Whether the filter's CUDA backend can run here (Localizer(device='cuda')): {'built': built with CUDA, "
      "'usable': a GPU it can use, 'reason': why not, 'device': the GPU's name}");
}
