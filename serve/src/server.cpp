#include "seqloc/serve/server.hpp"

#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include <httplib.h>

namespace seqloc::serve {

void ServerOptions::validate() const {
  auto fail = [](const std::string& what) { throw ServiceError("server option " + what); };
  if (port < 0 || port > 65535) fail("--port " + std::to_string(port) + ": must be in 0..65535");
  if (threads < 1 || threads > 4096) fail("--threads " + std::to_string(threads) + ": must be in 1..4096");
  if (max_pending < 0 || max_pending > 65536) fail("--max-pending " + std::to_string(max_pending) + ": must be in 0..65536");
  if (timeout_s < 1 || timeout_s > 3600) fail("--timeout " + std::to_string(timeout_s) + ": must be in 1..3600 s");
  if (keep_alive_s < 1 || keep_alive_s > 3600) fail("--keep-alive " + std::to_string(keep_alive_s) + ": must be in 1..3600 s");
}

namespace {

// Set on the thread that turns away connections beyond the limit: its requests get a 503.
thread_local bool t_overloaded = false;

/// httplib's task queue with a bound: `threads` workers, at most `max_pending` connections
/// waiting for one; any further connection goes to a single rejecting thread that answers 503
/// and closes it (the connection's task owns the socket, so it must run somewhere).
class BoundedPool : public httplib::TaskQueue {
 public:
  BoundedPool(int threads, int max_pending, std::atomic<std::uint64_t>& rejected, std::atomic<int>& busy_gauge)
      : limit_(static_cast<std::size_t>(threads) + static_cast<std::size_t>(max_pending)),
        rejected_(rejected),
        busy_gauge_(busy_gauge) {
    for (int i = 0; i < threads; ++i) workers_.emplace_back([this] { work(jobs_, false); });
    workers_.emplace_back([this] { work(rejects_, true); });
  }
  ~BoundedPool() override = default;
  BoundedPool(const BoundedPool&) = delete;
  BoundedPool& operator=(const BoundedPool&) = delete;

  void enqueue(std::function<void()> fn) override {
    {
      std::lock_guard lock(mutex_);
      if (busy_ + jobs_.size() < limit_) {
        jobs_.push_back(std::move(fn));
      } else {
        rejects_.push_back(std::move(fn));
        ++rejected_;
      }
    }
    ready_.notify_all();
  }

  void shutdown() override {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    ready_.notify_all();
    for (auto& t : workers_) t.join();
  }

 private:
  void work(std::deque<std::function<void()>>& queue, bool rejecting) {
    t_overloaded = rejecting;
    for (;;) {
      std::function<void()> fn;
      {
        std::unique_lock lock(mutex_);
        ready_.wait(lock, [&] { return stopping_ || !queue.empty(); });
        if (queue.empty()) return;  // stopping, nothing left
        fn = std::move(queue.front());
        queue.pop_front();
        if (!rejecting) ++busy_, ++busy_gauge_;
      }
      fn();
      if (!rejecting) {
        std::lock_guard lock(mutex_);
        --busy_, --busy_gauge_;
      }
    }
  }

  const std::size_t limit_;
  std::atomic<std::uint64_t>& rejected_;
  std::atomic<int>& busy_gauge_;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> jobs_, rejects_;
  std::size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

/// "http://HOST" from the Host header when it is a plain host[:port], else from the bound address.
std::string base_url(const httplib::Request& req, const std::string& fallback) {
  const std::string host = req.get_header_value("Host");
  if (host.empty() || host.size() > 255) return fallback;
  for (char c : host) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == ':' || c == '-' || c == '[' || c == ']')) {
      return fallback;
    }
  }
  return "http://" + host;
}

}  // namespace

class HttpServer::Impl {
 public:
  httplib::Server server;
  std::atomic<std::uint64_t> rejected{0};
  std::atomic<int> busy{0};
  std::mutex log_mutex;
  // httplib's stop() does nothing until listen has started running: these make a stop() that
  // comes first (a signal right after bind()) stop the listen that follows.
  std::atomic<bool> stop_requested{false}, listen_entered{false}, listen_returned{false};
};

HttpServer::HttpServer(Service& service, const ServerOptions& options) : impl_(std::make_unique<Impl>()) {
  options.validate();
  auto& svr = impl_->server;
  Impl* impl = impl_.get();
  svr.new_task_queue = [options, impl] { return new BoundedPool(options.threads, options.max_pending, impl->rejected, impl->busy);
  };
  svr.set_read_timeout(options.timeout_s, 0);
  svr.set_write_timeout(options.timeout_s, 0);
  svr.set_keep_alive_timeout(options.keep_alive_s);
  svr.set_keep_alive_max_count(10000);
  svr.set_payload_max_length(std::size_t{64} * 1024);
  svr.set_tcp_nodelay(true);
  const std::string fallback = "http://" + (options.bind.find(':') != std::string::npos ? "[" + options.bind + "]" : options.bind);
  svr.set_pre_routing_handler([&service, options, impl, fallback, this](const httplib::Request& req,
                                                                        httplib::Response& res) {
    if (t_overloaded) {
      res.status = 503;
      res.set_header("Connection", "close");
      res.set_header("Retry-After", "1");
      res.set_content(error_response(503, "the server is at its connection limit; retry shortly").text(),
                      "application/json");
      return httplib::Server::HandlerResponse::Handled;
    }
    // Our own strict decoding of the raw target (fuzzed in fuzz/request.cpp), not httplib's.
    Request request;
    try {
      request = parse_request(req.method, req.target);
    } catch (const RequestError& e) {
      res.status = 400;
      res.set_content(error_response(400, e.what()).text(), "application/json");
      return httplib::Server::HandlerResponse::Handled;
    }
    request.if_none_match = req.get_header_value("If-None-Match");
    request.base_url = base_url(req, fallback + ":" + std::to_string(port_));
    const Response response = service.handle(request);
    res.status = response.status;
    for (const auto& [key, value] : response.headers) res.set_header(key, value);
    res.set_header("Access-Control-Allow-Origin", "*");
    if (response.status != 304 && response.body) {
      // Sent straight from the (shared, immutable) body: no copy per request.
      std::shared_ptr<const std::string> body = response.body;
      res.set_content_provider(body->size(), response.content_type,
                               [body](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
                                 return sink.write(body->data() + offset, length);
                               });
    }
    if (options.access_log) {
      std::lock_guard lock(impl->log_mutex);
      std::fprintf(stderr, "%s %s %d %zu\n", req.method.c_str(), req.target.c_str(), res.status, response.text().size());
    }
    return httplib::Server::HandlerResponse::Handled;
  });
  options_copy_ = options;
}

HttpServer::~HttpServer() { stop(); }

void HttpServer::bind() {
  auto& svr = impl_->server;
  if (options_copy_.port == 0) {
    port_ = svr.bind_to_any_port(options_copy_.bind);
  } else if (svr.bind_to_port(options_copy_.bind, options_copy_.port)) {
    port_ = options_copy_.port;
  } else {
    port_ = -1;
  }
  if (port_ <= 0) {
    throw ServiceError("cannot listen on " + options_copy_.bind + ":" + std::to_string(options_copy_.port) +
                       " (address in use, or not an address of this machine)");
  }
}

void HttpServer::listen() {
  impl_->listen_entered = true;
  if (!impl_->stop_requested) impl_->server.listen_after_bind();
  impl_->listen_returned = true;
}

void HttpServer::stop() {
  if (!impl_) return;
  impl_->stop_requested = true;
  // Either listen() sees the request and does not start, or this sees listen() entered and waits
  // for it to be running (or to have returned) before stopping it.
  if (!impl_->listen_entered) return;
  while (!impl_->server.is_running() && !impl_->listen_returned) std::this_thread::yield();
  impl_->server.stop();
}

std::uint64_t HttpServer::rejected() const { return impl_->rejected.load(); }

int HttpServer::busy_workers() const { return impl_->busy.load(); }

}  // namespace seqloc::serve
