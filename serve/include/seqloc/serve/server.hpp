#pragma once
// `seqloc serve` (docs/serve.md): the Service behind HTTP/1.1 (cpp-httplib). A fixed pool of
// worker threads serves the connections; a connection that finds every worker busy gets an
// immediate 503 instead of waiting without bound. Reads and writes time out, request bodies are
// refused, and only loopback is bound unless told otherwise.

#include <atomic>
#include <memory>
#include <string>

#include "seqloc/serve/service.hpp"

namespace seqloc::serve {

struct ServerOptions {
  std::string bind = "127.0.0.1";
  int port = 8080;                ///< 0: any free port (see HttpServer::port())
  int threads = 64;               ///< workers, each serving one connection at a time
  int max_pending = 64;           ///< connections waiting for a worker before 503s
  int timeout_s = 10;             ///< read and write timeout of a connection
  int keep_alive_s = 5;           ///< idle time before a keep-alive connection is closed
  bool access_log = false;        ///< one line per request on stderr

  /// Names the field, its value and the constraint it breaks.
  void validate() const;
};

class HttpServer {
 public:
  HttpServer(Service& service, const ServerOptions& options);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  /// Binds the socket (throws ServiceError naming the address when it cannot).
  void bind();
  /// The bound port.
  [[nodiscard]] int port() const { return port_; }
  /// Serves until stop() (from another thread or a signal handler's thread).
  void listen();
  void stop();

  /// Connections turned away at the limit so far.
  [[nodiscard]] std::uint64_t rejected() const;
  /// Workers serving a connection now.
  [[nodiscard]] int busy_workers() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
  ServerOptions options_copy_;
  int port_ = 0;
};

}  // namespace seqloc::serve
