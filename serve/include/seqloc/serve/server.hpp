#pragma once
// `seqloc serve` (docs/serve.md): the Service behind HTTP/1.1, on an event-driven layer
// (Boost.Beast over Asio). No thread waits on a socket: a few threads run one event loop that
// accepts, reads request heads and writes responses for every connection, and compute the
// answer of each complete request. So thousands of slow, idle or half-open clients cost
// memory (a few KiB each), never a thread, and well-formed requests keep their latency. Each
// phase of a connection has its own deadline; connections are bounded in total and per client
// address; request heads and bodies are bounded in size; only loopback is bound unless told
// otherwise.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "seqloc/serve/service.hpp"

namespace seqloc::serve {

struct ServerOptions {
  std::string bind = "127.0.0.1";
  int port = 8080;              ///< 0: any free port (see HttpServer::port())
  int threads = 4;              ///< threads running the event loop and computing answers
  double header_timeout_s = 5;  ///< a request head must arrive within this from its first byte
                                ///< (a new connection's first head: from the connection)
  double keep_alive_s = 15;     ///< idle time between requests before a connection is closed
  double timeout_s = 10;        ///< to send a response, or to receive a request body
  int max_connections = 10000;  ///< open connections; past it new ones get a 503 and are closed
  int max_per_client = 256;     ///< open connections from one client address
  std::size_t max_header_bytes = std::size_t{16} * 1024;  ///< request line plus headers; past it a 431
  std::size_t max_body_bytes = std::size_t{64} * 1024;    ///< request body; past it a 413 (nothing takes a body)
  bool access_log = false;                                ///< one line per request on stderr

  /// Names the field, its value and the constraint it breaks.
  void validate() const;
};

class HttpServer {
 public:
  HttpServer(Service& service, const ServerOptions& options);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  /// Binds the socket (throws ServiceError naming the address when it cannot). Raises the
  /// process's open-file limit towards what --max-connections needs (see max_connections()).
  void bind();
  /// The bound port.
  [[nodiscard]] int port() const { return port_; }
  /// The connection limit in force: --max-connections, lowered when the open-file limit the
  /// system allows cannot hold that many sockets.
  [[nodiscard]] int max_connections() const;
  /// Serves until stop() (from another thread or a signal handler's thread); then closes every
  /// connection and returns.
  void listen();
  /// Stops accepting and closes every connection; requests being answered are cut off. Safe from
  /// any thread, before or during listen(), any number of times.
  void stop();

  /// Connections turned away at a limit so far (total or per client).
  [[nodiscard]] std::uint64_t rejected() const;
  /// Connections open now.
  [[nodiscard]] int open_connections() const;
  /// Connections closed for missing a deadline so far (head, idle, body or send).
  [[nodiscard]] std::uint64_t timed_out() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
};

}  // namespace seqloc::serve
