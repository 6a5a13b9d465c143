#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>

#include <avp/core/status.h>
#include <avp/segmentation_service/segmentation_server.h>

namespace avp::apps {

// ---- avp serve segmentation ---------------------------------------------------------------------

enum class ServeLogLevel { kInfo, kWarning };

/// `avp serve segmentation`: the segmentation service (docs/segmentation-service.md) until SIGINT
/// or SIGTERM, then a clean shutdown (running calls finish, for up to `grace_s`).
struct ServeOptions {
  /// Host, port (0 = pick one), backends, threads, ... (the command's default host is 0.0.0.0).
  segmentation_service::ServerOptions server;
  /// When set, the bound port is written there (one line, atomically) once the server listens:
  /// scripts wait for it instead of sleeping.
  std::filesystem::path port_file;
  /// Seconds running calls get to finish at shutdown.
  double grace_s = 5.0;
  /// Where the address, each backend's state and the shutdown are reported (stdout if null).
  std::function<void(ServeLogLevel, const std::string&)> log;
  /// Also stops the server when it becomes true (polled every 100 ms; tests). May be null.
  const std::atomic<bool>* stop = nullptr;
};

/// Starts the server, logs "serving segmentation on HOST:PORT" and one line per backend
/// ("model 'oracle': READY" or "model 'x': NOT READY: <reason>"), waits for SIGINT / SIGTERM
/// (blocked in every thread the server starts, and waited for with sigtimedwait), then shuts
/// down. Backends that cannot be built are warnings, not errors. Errors: bad options, an address
/// that cannot be bound, a port file that cannot be written.
Status RunServeSegmentation(const ServeOptions& options);

}  // namespace avp::apps
