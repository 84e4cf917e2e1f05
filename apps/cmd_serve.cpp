#include <csignal>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/pipeline/region_catalog.hpp"
#include "seqloc/serve/server.hpp"
#include "seqloc/serve/service.hpp"

namespace seqloc::app {
namespace {

class ServeCommand : public Command {
 public:
  void setup(CLI::App& app) override {
    app.add_option("caches", caches_, "Region caches (GeoPackage), or folders of them; each is a region named after its file")
        ->required()
        ->check(CLI::ExistingPath);
    app.add_option("--bind", server_.bind, "Address to listen on (loopback unless told otherwise)")
        ->capture_default_str();
    app.add_option("--port", server_.port, "Port (0: any free port, printed at start)")->capture_default_str();
    app.add_option("--threads", server_.threads,
                   "Threads running the event loop and answering requests (no thread waits on a client)")
        ->capture_default_str();
    app.add_option("--header-timeout", server_.header_timeout_s,
                   "Seconds for a request head to arrive, from its first byte (a new connection: from its opening)")
        ->capture_default_str();
    app.add_option("--keep-alive", server_.keep_alive_s, "Seconds a connection may stay idle between requests")
        ->capture_default_str();
    app.add_option("--timeout", server_.timeout_s, "Seconds to send a response or receive a request body")
        ->capture_default_str();
    app.add_option("--max-connections", server_.max_connections,
                   "Open connections; past it new ones get a 503 and are closed")
        ->capture_default_str();
    app.add_option("--max-per-client", server_.max_per_client, "Open connections from one client address")
        ->capture_default_str();
    app.add_option("--reload-check", service_.reload_check_s,
                   "Seconds between checks for a replaced cache file (0: every request, -1: never)")
        ->capture_default_str();
    app.add_option("--max-crop-m", service_.max_crop_m, "Largest crop side served, metres")->capture_default_str();
    app.add_option("--prior-sigma", service_.layers.prior_sigma_m, "Sigma of the road_prior layer, metres")
        ->capture_default_str();
    app.add_option("--web", web_, "Directory of the viewer page (default: the one built with seqloc, if any)");
    app.add_flag("--access-log", server_.access_log, "One line per request on stderr");
  }

  void check() override {
    // Usage errors (ServiceError's category): exit 2.
    service_.validate();  // --max-crop-m, --prior-sigma, ...
    server_.validate();
  }

  int run() override {
    if (!web_.empty()) {
      service_.web_root = web_;
    } else if (std::error_code ec; std::filesystem::is_regular_file(std::filesystem::path(SEQLOC_WEB_DIR) / "index.html", ec)) {
      service_.web_root = SEQLOC_WEB_DIR;
    }
    // SIGINT and SIGTERM are taken by one thread with sigwait, which stops the server cleanly;
    // every other thread inherits the blocked mask.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);

    service_.on_reload = [](const std::string& id, const std::string& error) {
      if (error.empty()) {
        std::fprintf(stderr, "seqloc serve: region '%s' reloaded (its cache file was replaced)\n", id.c_str());
      } else {
        std::fprintf(stderr, "seqloc serve: region '%s': the replaced cache file is not served (%s); the previous one "
                     "stays\n", id.c_str(), error.c_str());
      }
    };
    caches_ = pipeline::region_cache_files(caches_);
    serve::Service service(caches_, service_);
    serve::HttpServer server(service, server_);
    server.bind();
    if (server.max_connections() < server_.max_connections) {
      std::fprintf(stderr, "seqloc serve: the open-file limit allows %d connections, not --max-connections %d "
                   "(raise it with ulimit -n)\n", server.max_connections(), server_.max_connections);
    }
    std::printf("seqloc serve: http://%s:%d/ (%zu region%s: ", server_.bind.c_str(), server.port(), caches_.size(),
                caches_.size() == 1 ? "" : "s");
    const auto ids = service.region_ids();
    for (std::size_t i = 0; i < ids.size(); ++i) std::printf("%s%s", i ? ", " : "", ids[i].c_str());
    std::printf(")%s\n", service_.web_root.empty() ? "; no viewer page" : "");
    std::fflush(stdout);
    std::thread waiter([&] {
      int signal = 0;
      sigwait(&signals, &signal);
      server.stop();
    });
    server.listen();
    // listen() also returns when the socket fails: wake the waiter either way. SIGTERM is blocked
    // and taken by its sigwait, so this wakes the thread, it does not terminate it.
    pthread_kill(waiter.native_handle(), SIGTERM);  // NOLINT(bugprone-bad-signal-to-kill-thread)
    waiter.join();
    std::fprintf(stderr,
                 "seqloc serve: stopped after %llu requests (%llu connections turned away at a limit, %llu closed "
                 "at a deadline)\n",
                 static_cast<unsigned long long>(service.stats().requests),
                 static_cast<unsigned long long>(server.rejected()),
                 static_cast<unsigned long long>(server.timed_out()));
    return kExitOk;
  }

 private:
  std::vector<std::filesystem::path> caches_;
  serve::ServerOptions server_;
  serve::ServiceOptions service_;
  std::filesystem::path web_;
};

}  // namespace

std::unique_ptr<Command> make_serve_command() { return std::make_unique<ServeCommand>(); }

}  // namespace seqloc::app
