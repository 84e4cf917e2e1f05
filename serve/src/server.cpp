#include "seqloc/serve/server.hpp"

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

#include <boost/asio/dispatch.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>

namespace seqloc::serve {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using error_code = boost::system::error_code;

void ServerOptions::validate() const {
  auto fail = [](const std::string& what) { throw ServiceError("server option " + what, ErrorCategory::usage); };
  auto seconds = [&](const char* name, double value) {
    if (!(value >= 0.1 && value <= 3600))
      fail(std::string(name) + " " + std::to_string(value) + ": must be in 0.1..3600 s");
  };
  if (port < 0 || port > 65535) fail("--port " + std::to_string(port) + ": must be in 0..65535");
  if (threads < 1 || threads > 1024) fail("--threads " + std::to_string(threads) + ": must be in 1..1024");
  seconds("--header-timeout", header_timeout_s);
  seconds("--keep-alive", keep_alive_s);
  seconds("--timeout", timeout_s);
  if (max_connections < 1 || max_connections > 1000000) {
    fail("--max-connections " + std::to_string(max_connections) + ": must be in 1..1000000");
  }
  if (max_per_client < 1 || max_per_client > max_connections) {
    fail("--max-per-client " + std::to_string(max_per_client) + ": must be in 1..--max-connections (" +
         std::to_string(max_connections) + ")");
  }
  if (max_header_bytes < 1024 || max_header_bytes > (1u << 20)) {
    fail("max_header_bytes " + std::to_string(max_header_bytes) + ": must be in 1024..1048576");
  }
  if (max_body_bytes > (64u << 20))
    fail("max_body_bytes " + std::to_string(max_body_bytes) + ": must be at most 64 MiB");
}

namespace {

/// File descriptors kept free of connections: the caches, the viewer's files, the listener.
constexpr int kReservedFiles = 256;

std::chrono::steady_clock::duration seconds_duration(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(s));
}

/// "http://HOST" from the Host header when it is a plain host[:port], else the fallback.
std::string base_url(std::string_view host, const std::string& fallback) {
  if (host.empty() || host.size() > 255) return fallback;
  for (char c : host) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == ':' || c == '-' || c == '[' || c == ']')) {
      return fallback;
    }
  }
  return "http://" + std::string(host);
}

/// The client's address, an IPv4 client on a dual-stack socket as IPv4 (one client, one key).
asio::ip::address client_address(const asio::ip::address& address) {
  if (address.is_v6() && address.to_v6().is_v4_mapped()) {
    return asio::ip::make_address_v4(asio::ip::v4_mapped, address.to_v6());
  }
  return address;
}

class Connection;

/// What every connection shares: the loop, the service, the limits and the books.
struct Core {
  Core(Service& service_, ServerOptions options_) : service(service_), options(std::move(options_)) {}

  Service& service;
  const ServerOptions options;
  std::string fallback_base;  ///< "http://ADDRESS:PORT", when a request has no usable Host
  int max_connections = 0;    ///< the limit in force (bind() may lower --max-connections)

  std::atomic<bool> stopping{false};
  std::atomic<std::uint64_t> rejected{0}, timed_out{0};
  std::atomic<int> open{0};
  std::mutex log_mutex;

  // The open connections (to close them on stop) and their count per client address. Declared
  // before the loop: connections still queued in it are destroyed with it, and unregister here.
  std::mutex books_mutex;
  std::unordered_map<std::uint64_t, std::weak_ptr<Connection>> connections;  ///< guarded by books_mutex
  std::map<asio::ip::address, int> per_client;                               ///< guarded by books_mutex
  std::uint64_t next_id = 0;                                                 ///< guarded by books_mutex

  asio::io_context loop;
  // The acceptor and its retry timer live on one strand, which stop() posts to as well.
  asio::strand<asio::io_context::executor_type> accept_strand = asio::make_strand(loop);
  tcp::acceptor acceptor{accept_strand};
  asio::steady_timer accept_pause{accept_strand};

  void accept();
  void on_accept(const error_code& ec, tcp::socket socket);
  void forget(std::uint64_t id, const asio::ip::address& client);
  void stop();
};

/// One client connection: reads a request head under its deadline, answers it, and waits for
/// the next under the idle deadline. Every step runs on the connection's strand.
class Connection : public std::enable_shared_from_this<Connection> {
 public:
  Connection(Core& core, tcp::socket socket, asio::ip::address client, std::uint64_t id)
      : core_(core),
        stream_(std::move(socket)),
        buffer_(core.options.max_header_bytes + 4096),
        client_(std::move(client)),
        id_(id) {}
  ~Connection() { core_.forget(id_, client_); }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  void start() { read_head(true); }
  void close() {
    error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
    stream_.socket().close(ignored);
  }
  [[nodiscard]] auto executor() { return stream_.get_executor(); }

 private:
  void read_head(bool first) {
    if (core_.stopping) return close();
    parser_.emplace();
    parser_->header_limit(static_cast<std::uint32_t>(core_.options.max_header_bytes));
    parser_->body_limit(core_.options.max_body_bytes);
    if (first || buffer_.size() > 0) {
      // A new connection's first head, or a pipelined one already here: the head deadline runs now.
      read_rest_of_head();
      return;
    }
    // Idle between requests: wait for the first byte under the keep-alive deadline.
    stream_.expires_after(seconds_duration(core_.options.keep_alive_s));
    stream_.async_read_some(buffer_.prepare(4096), [self = shared_from_this()](const error_code& ec, std::size_t n) {
      if (ec) return self->drop(ec);
      self->buffer_.commit(n);
      self->read_rest_of_head();
    });
  }

  void read_rest_of_head() {
    stream_.expires_after(seconds_duration(core_.options.header_timeout_s));
    http::async_read_header(stream_, buffer_, *parser_,
                            [self = shared_from_this()](const error_code& ec, std::size_t) { self->on_head(ec); });
  }

  void on_head(const error_code& ec) {
    if (ec == http::error::header_limit || ec == http::error::buffer_overflow) {
      return refuse(431, "the request head is over " + std::to_string(core_.options.max_header_bytes) + " bytes");
    }
    if (ec == http::error::body_limit) return refuse_body();  // a Content-Length over the limit
    if (is_parse_error(ec)) return refuse(400, "malformed HTTP request: " + ec.message());
    if (ec) return drop(ec);
    if (parser_->is_done()) return answer();
    // A (small) body: read and ignored, under the send/receive deadline.
    stream_.expires_after(seconds_duration(core_.options.timeout_s));
    http::async_read(stream_, buffer_, *parser_, [self = shared_from_this()](const error_code& e, std::size_t) {
      if (e == http::error::body_limit) return self->refuse_body();  // chunks past the limit
      if (is_parse_error(e)) return self->refuse(400, "malformed HTTP request body: " + e.message());
      if (e) return self->drop(e);
      self->answer();
    });
  }

  void refuse_body() {
    refuse(413,
           "a request body over " + std::to_string(core_.options.max_body_bytes) + " bytes (no endpoint takes one)");
  }

  static bool is_parse_error(const error_code& ec) {
    return ec.category() == http::make_error_code(http::error::bad_method).category() &&
           ec != http::error::end_of_stream && ec != http::error::partial_message && ec != http::error::need_more;
  }

  void answer() {
    const auto& req = parser_->get();
    const std::string_view method(req.method_string().data(), req.method_string().size());
    const std::string_view target(req.target().data(), req.target().size());
    Response response;
    try {
      // Our own strict decoding of the raw target (fuzzed in fuzz/request.cpp).
      Request request = parse_request(method, target);
      const auto etag = req[http::field::if_none_match];
      request.if_none_match.assign(etag.data(), etag.size());
      const auto host = req[http::field::host];
      request.base_url = base_url(std::string_view(host.data(), host.size()), core_.fallback_base);
      response = core_.service.handle(request);
    } catch (const std::exception& e) {
      // A malformed target (400); out of memory, say: this request fails, not the server.
      const int status = http_status(e);
      response = error_response(status, status == 500 ? std::string("internal error: ") + e.what() : e.what());
    }
    if (core_.options.access_log) {
      std::lock_guard lock(core_.log_mutex);
      std::fprintf(stderr, "%.*s %.*s %d %zu\n", static_cast<int>(method.size()), method.data(),
                   static_cast<int>(target.size()), target.data(), response.status, response.text().size());
    }
    send(response, req.keep_alive() && !core_.stopping, method == "HEAD");
  }

  /// Answers with an error and closes: what follows in the stream cannot be trusted.
  void refuse(int status, const std::string& message) { send(error_response(status, message), false, false); }

  void send(const Response& response, bool keep_alive, bool head) {
    response_.emplace(static_cast<http::status>(response.status), 11);
    for (const auto& [key, value] : response.headers) response_->set(key, value);
    response_->set(http::field::access_control_allow_origin, "*");
    if (response.status != 304 && response.body) {
      // Sent straight from the (shared, immutable) body: no copy per request.
      body_ = response.body;
      response_->set(http::field::content_type, response.content_type);
      if (!head) response_->body() = http::span_body<const char>::value_type(body_->data(), body_->size());
      response_->content_length(body_->size());
    }
    response_->keep_alive(keep_alive);
    stream_.expires_after(seconds_duration(core_.options.timeout_s));
    http::async_write(stream_, *response_, [self = shared_from_this(), keep_alive](const error_code& ec, std::size_t) {
      if (ec) return self->drop(ec);
      self->response_.reset();
      self->body_.reset();
      if (!keep_alive) return self->close();
      self->read_head(false);
    });
  }

  /// The connection ends: the client went away, a deadline passed, or the server stops.
  void drop(const error_code& ec) {
    if (ec == beast::error::timeout) ++core_.timed_out;
    close();
  }

  Core& core_;
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;  ///< bounded: a head over the limit is a 431, not more memory
  std::optional<http::request_parser<http::string_body>> parser_;
  std::optional<http::response<http::span_body<const char>>> response_;
  std::shared_ptr<const std::string> body_;  ///< what response_ points into, while it is sent
  asio::ip::address client_;
  std::uint64_t id_;
};

void Core::accept() {
  acceptor.async_accept(asio::make_strand(loop),
                        [this](const error_code& ec, tcp::socket socket) { on_accept(ec, std::move(socket)); });
}

void Core::on_accept(const error_code& ec, tcp::socket socket) {
  if (stopping || ec == asio::error::operation_aborted) return;
  if (ec) {
    // Out of file descriptors (or a connection reset before it was taken): try again shortly
    // rather than spin on the error.
    accept_pause.expires_after(std::chrono::milliseconds(50));
    accept_pause.async_wait([this](const error_code& e) {
      if (!e && !stopping) accept();
    });
    return;
  }
  accept();
  error_code e;
  const auto endpoint = socket.remote_endpoint(e);
  if (e) return;  // gone already
  const auto client = client_address(endpoint.address());
  std::uint64_t id = 0;
  bool admitted = false;
  {
    std::lock_guard lock(books_mutex);
    int& from_client = per_client[client];
    if (open.load() < max_connections && from_client < options.max_per_client) {
      ++from_client;
      ++open;
      id = next_id++;
      admitted = true;
    } else if (from_client == 0) {
      per_client.erase(client);
    }
  }
  if (!admitted) {
    // A short answer the client can read if it is listening, sent without waiting, then closed.
    ++rejected;
    static const std::string kBusy = [] {
      const std::string body = error_response(503, "the server is at its connection limit; retry shortly").text();
      return "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nRetry-After: 1\r\n"
             "Connection: close\r\nContent-Length: " +
             std::to_string(body.size()) + "\r\n\r\n" + body;
    }();
    socket.non_blocking(true, e);
    socket.send(asio::buffer(kBusy), 0, e);
    socket.shutdown(tcp::socket::shutdown_send, e);
    socket.close(e);
    return;
  }
  socket.set_option(tcp::no_delay(true), e);
  auto connection = std::make_shared<Connection>(*this, std::move(socket), client, id);
  {
    std::lock_guard lock(books_mutex);
    connections.emplace(id, connection);
  }
  asio::dispatch(connection->executor(), [connection] { connection->start(); });
}

void Core::forget(std::uint64_t id, const asio::ip::address& client) {
  std::lock_guard lock(books_mutex);
  connections.erase(id);
  if (auto it = per_client.find(client); it != per_client.end() && --it->second <= 0) per_client.erase(it);
  --open;
}

void Core::stop() {
  if (stopping.exchange(true)) return;
  asio::post(accept_strand, [this] {
    error_code ignored;
    acceptor.close(ignored);
    accept_pause.cancel();
    std::vector<std::shared_ptr<Connection>> live;
    {
      std::lock_guard lock(books_mutex);
      for (const auto& entry : connections) {
        if (auto c = entry.second.lock()) live.push_back(std::move(c));
      }
    }
    // Each is closed on its own strand; its pending operations end and release it, and the loop
    // runs out of work.
    for (auto& c : live) asio::post(c->executor(), [c] { c->close(); });
  });
}

}  // namespace

class HttpServer::Impl {
 public:
  Impl(Service& service, const ServerOptions& options) : core(service, options) {}
  Core core;
};

HttpServer::HttpServer(Service& service, const ServerOptions& options) {
  options.validate();
  impl_ = std::make_unique<Impl>(service, options);
  impl_->core.max_connections = options.max_connections;
}

HttpServer::~HttpServer() { stop(); }

void HttpServer::bind() {
  Core& core = impl_->core;
  const auto& options = core.options;
  const auto fail = [&](const std::string& why) {
    throw ServiceError("cannot listen on " + options.bind + ":" + std::to_string(options.port) + " (" + why + ")",
                       ErrorCategory::io);
  };
  error_code ec;
  tcp::endpoint endpoint;
  if (const auto address = asio::ip::make_address(options.bind, ec); !ec) {
    endpoint = tcp::endpoint(address, static_cast<unsigned short>(options.port));
  } else {
    tcp::resolver resolver(core.loop);
    const auto results = resolver.resolve(options.bind, std::to_string(options.port), ec);
    if (ec || results.empty()) fail("not an address of this machine");
    endpoint = results.begin()->endpoint();
  }
  if (core.acceptor.open(endpoint.protocol(), ec); ec) fail(ec.message());
  core.acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (core.acceptor.bind(endpoint, ec); ec) fail(ec.message());
  if (core.acceptor.listen(asio::socket_base::max_listen_connections, ec); ec) fail(ec.message());
  port_ = core.acceptor.local_endpoint().port();
  const std::string host =
      endpoint.address().is_v6() ? "[" + endpoint.address().to_string() + "]" : endpoint.address().to_string();
  core.fallback_base = "http://" + host + ":" + std::to_string(port_);

  // Each connection is a file descriptor: raise the soft limit as far as the hard one allows,
  // and lower the connection limit to what fits.
  rlimit files{};
  if (getrlimit(RLIMIT_NOFILE, &files) == 0) {
    const auto wanted = static_cast<rlim_t>(options.max_connections) + kReservedFiles;
    if (files.rlim_cur < wanted) {
      rlimit raised = files;
      raised.rlim_cur = files.rlim_max == RLIM_INFINITY ? wanted : std::min(wanted, files.rlim_max);
      if (setrlimit(RLIMIT_NOFILE, &raised) == 0) files = raised;
    }
    if (files.rlim_cur != RLIM_INFINITY && files.rlim_cur < wanted) {
      core.max_connections = std::max<int>(1, static_cast<int>(files.rlim_cur) - kReservedFiles);
    }
  }
}

int HttpServer::max_connections() const { return impl_->core.max_connections; }

void HttpServer::listen() {
  Core& core = impl_->core;
  if (!core.stopping) asio::post(core.accept_strand, [&core] { core.accept(); });
  std::vector<std::thread> helpers;
  for (int i = 1; i < core.options.threads; ++i) helpers.emplace_back([&core] { core.loop.run(); });
  core.loop.run();
  for (auto& t : helpers) t.join();
}

void HttpServer::stop() {
  if (impl_) impl_->core.stop();
}

std::uint64_t HttpServer::rejected() const { return impl_->core.rejected.load(); }

int HttpServer::open_connections() const { return impl_->core.open.load(); }

std::uint64_t HttpServer::timed_out() const { return impl_->core.timed_out.load(); }

}  // namespace seqloc::serve
