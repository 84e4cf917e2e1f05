// seqloc's errors as Python exceptions (docs/python.md, "Errors").

#include "bindings.hpp"

namespace seqloc::python {

// seqloc's errors as Python exceptions in this one place, by their category alone: seqloc.Error is
// the base; seqloc.UsageError and seqloc.DataError are ValueErrors, seqloc.NotFoundError a
// UsageError and a LookupError, seqloc.IOError an OSError, seqloc.InternalError a RuntimeError.
// The names of the earlier module's classes stay, as the category classes they were raised for:
// seqloc.CacheError is seqloc.IOError, seqloc.FilterError seqloc.DataError and seqloc.RequestError
// seqloc.UsageError.
void register_errors(py::module_& m) {
  // Each class lives as long as the module (released: never decremented after the interpreter ends).
  const auto make = [&m](const char* name, py::handle bases, const char* doc) {
    py::object type = py::reinterpret_steal<py::object>(
        PyErr_NewExceptionWithDoc((std::string("seqloc.") + name).c_str(), doc, bases.ptr(), nullptr));
    if (!type) throw py::error_already_set();
    m.attr(name) = type;
    return type;
  };
  static const py::handle error = make("Error", PyExc_Exception, "Base of every error seqloc raises.").release();
  static const py::handle usage = make("UsageError", py::make_tuple(error, py::handle(PyExc_ValueError)),
                                       "A request that cannot be carried out as given.")
                                      .release();
  static const py::handle not_found = make("NotFoundError", py::make_tuple(usage, py::handle(PyExc_LookupError)),
                                           "A request for what is not there: a point or tile outside the region.")
                                          .release();
  static const py::handle data =
      make("DataError", py::make_tuple(error, py::handle(PyExc_ValueError)), "Input data that cannot be used.")
          .release();
  static const py::handle io = make("IOError", py::make_tuple(error, py::handle(PyExc_OSError)),
                                    "A file that cannot be opened, read or written.")
                                   .release();
  static const py::handle internal = make("InternalError", py::make_tuple(error, py::handle(PyExc_RuntimeError)),
                                          "A broken invariant of seqloc itself.")
                                         .release();
  m.attr("CacheError") = io;
  m.attr("FilterError") = data;
  m.attr("RequestError") = usage;
  usage_type_error_class = make("UsageTypeError", py::make_tuple(usage, py::handle(PyExc_TypeError)),
                                "An argument of a type seqloc cannot use.")
                               .release();
  usage_key_error_class = make("UsageKeyError", py::make_tuple(usage, py::handle(PyExc_KeyError)),
                               "A name seqloc does not know (a filter setting, say).")
                              .release();
  usage_index_error_class =
      make("UsageIndexError", py::make_tuple(usage, py::handle(PyExc_IndexError)), "An index outside what it indexes.")
          .release();
  py::register_exception_translator([](std::exception_ptr p) {
    if (!p) return;
    try {
      std::rethrow_exception(p);
    } catch (const seqloc::Error& e) {
      py::handle type = internal;
      switch (e.category()) {
        case seqloc::ErrorCategory::usage:
          type = usage;
          break;
        case seqloc::ErrorCategory::not_found:
          type = not_found;
          break;
        case seqloc::ErrorCategory::data:
          type = data;
          break;
        case seqloc::ErrorCategory::io:
          type = io;
          break;
        case seqloc::ErrorCategory::internal:
          break;
      }
      PyErr_SetString(type.ptr(), e.what());
    } catch (const py::error_already_set&) {
      throw;  // a Python exception already (ours, or Python's own)
    } catch (const py::builtin_exception&) {
      throw;  // pybind11's own (an argument that does not convert, StopIteration)
    } catch (const std::bad_alloc&) {
      throw;  // MemoryError
    } catch (const std::exception& e) {
      // Anything else escaping seqloc is a bug of ours, not a bare RuntimeError.
      PyErr_SetString(internal.ptr(), e.what());
    }
  });
}

}  // namespace seqloc::python
