// Fuzz target: the server's request handling without sockets (serve/service.hpp): our decoding
// of the raw request target, then routing, parameter parsing, tiles, crops and points against a
// cache of the sample region, built once per process. Input: "METHOD TARGET", optionally a
// newline and the If-None-Match value.
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "fuzz_support.hpp"
#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/serve/service.hpp"

namespace {

// Destroyed in reverse order at exit: the service (its open cache) before the directory.
std::unique_ptr<seqloc::fuzz::ScratchDir> scratch;
std::unique_ptr<seqloc::serve::Service> service;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  scratch = std::make_unique<seqloc::fuzz::ScratchDir>("serve");
  seqloc::ingest::PreprocessOptions options;
  options.input = SEQLOC_SAMPLE_PBF;
  options.output = scratch->path() / "valley.gpkg";
  options.threads = 1;
  (void)seqloc::ingest::preprocess_region(options);
  seqloc::serve::ServiceOptions service_options;
  service_options.response_cache_bytes = 4u << 20;  // evictions happen during a run too
  service = std::make_unique<seqloc::serve::Service>(std::vector{options.output}, service_options);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const auto [line, etag] = seqloc::fuzz::split_once(input, "\n");
  const auto [method, target] = seqloc::fuzz::split_once(line, " ");
  seqloc::serve::Request request;
  try {
    request = seqloc::serve::parse_request(method, target);
  } catch (const seqloc::serve::RequestError& e) {
    if (e.kind() != seqloc::serve::RequestError::Kind::bad_request) std::abort();
    return 0;
  }
  request.if_none_match = std::string(etag);
  const auto response = service->handle(request);  // promises never to throw
  if (response.status < 200 || response.status > 599) std::abort();
  if (response.status != 304 && !response.body) std::abort();
  return 0;
}
