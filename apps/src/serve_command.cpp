#include "serve_command.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include <fmt/format.h>
#include <pthread.h>
#include <spdlog/spdlog.h>

#include <avp/io/file.h>
#include <avp/zsl/register.h>
#ifdef AVP_WITH_ONNX
#include <avp/zsl/model_service.h>
#include <avp/zsl/zsl.h>
#endif

#include "cli_common.h"

namespace avp::apps {

namespace {

/// Blocks SIGINT and SIGTERM in this thread (and so in every thread started after) for its
/// lifetime, restoring the previous mask after.
class ScopedSignalBlock {
 public:
  ScopedSignalBlock() {
    sigemptyset(&set_);
    sigaddset(&set_, SIGINT);
    sigaddset(&set_, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set_, &previous_);
  }
  ~ScopedSignalBlock() {
    // Drop signals that arrived while blocked, so restoring the mask does not deliver them.
    timespec zero{0, 0};
    while (sigtimedwait(&set_, nullptr, &zero) > 0) {
    }
    pthread_sigmask(SIG_SETMASK, &previous_, nullptr);
  }
  ScopedSignalBlock(const ScopedSignalBlock&) = delete;
  ScopedSignalBlock& operator=(const ScopedSignalBlock&) = delete;

  /// The signal that arrived within `timeout_ms`, or 0.
  int Wait(long timeout_ms) const {
    timespec timeout{timeout_ms / 1000, (timeout_ms % 1000) * 1'000'000};
    const int signal = sigtimedwait(&set_, nullptr, &timeout);
    return signal > 0 ? signal : 0;
  }

 private:
  sigset_t set_{};
  sigset_t previous_{};
};

}  // namespace

Status RunServeSegmentation(const ServeOptions& options) {
  const auto log = [&](ServeLogLevel level, const std::string& message) {
    if (options.log) {
      options.log(level, message);
    } else {
      std::printf("%s%s\n", level == ServeLogLevel::kWarning ? "warning: " : "", message.c_str());
      std::fflush(stdout);
    }
  };
  if (!(options.grace_s >= 0.0 && options.grace_s <= 600.0)) {
    return InvalidArgumentError(
        fmt::format("serve: grace_s ({}) must be in [0, 600] seconds", options.grace_s));
  }
  // Before any server thread exists, so that every one inherits the mask and the signals reach
  // the Wait below instead of killing the process.
  const ScopedSignalBlock signals;
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<segmentation_service::SegmentationServer> server,
                       segmentation_service::SegmentationServer::Start(options.server));
  log(ServeLogLevel::kInfo,
      fmt::format("serving segmentation (KServe v2 / Open Inference Protocol, gRPC) on {} with {} "
                  "worker threads; queue {} ({} per client); per request at most {} pixels, a "
                  "{}-byte prompt of {} phrases, {} instances",
                  server->address(), options.server.threads, options.server.max_queue_depth,
                  options.server.max_queued_per_client, options.server.max_image_pixels,
                  options.server.max_prompt_bytes, options.server.max_prompt_phrases,
                  options.server.max_instances));
  int ready = 0;
  for (const segmentation_service::ModelState& m : server->models()) {
    if (m.ready) {
      ++ready;
      log(ServeLogLevel::kInfo, fmt::format("model '{}': READY", m.name));
    } else {
      log(ServeLogLevel::kWarning, fmt::format("model '{}': NOT READY: {}", m.name, m.reason));
    }
  }
  if (ready == 0) {
    log(ServeLogLevel::kWarning, "no model is ready: every request will be refused");
  }
#ifdef AVP_WITH_ONNX
  // Networks shared by the instances and batched (--max-batch, AVP_ZSL_MAX_BATCH).
  for (const zsl::BatchedNetwork& n : zsl::BatchedNetworks()) {
    log(ServeLogLevel::kInfo, fmt::format("network '{}' ({}): shared by the instances, batched: {}",
                                          n.role, n.file, n.options.Describe()));
  }
#endif
  if (!options.port_file.empty()) {
    const Status written =
        io::WriteFileAtomic(options.port_file, fmt::format("{}\n", server->port()), "port file");
    if (!written.ok()) {
      server->Shutdown(std::chrono::milliseconds(0));
      return written;
    }
  }
  int signal = 0;
  while (signal == 0) {
    if (options.stop != nullptr && options.stop->load()) break;
    signal = signals.Wait(100);
  }
  log(ServeLogLevel::kInfo, fmt::format("{}: shutting down (running calls get {} s)",
                                        signal == SIGINT    ? "SIGINT"
                                        : signal == SIGTERM ? "SIGTERM"
                                                            : "stop requested",
                                        options.grace_s));
  server->Shutdown(std::chrono::milliseconds(static_cast<long>(options.grace_s * 1000.0)));
  if (!options.port_file.empty()) {
    std::error_code ignored;
    std::filesystem::remove(options.port_file, ignored);  // no stale port for the next script
  }
  const segmentation_service::ServerStats stats = server->stats();
  log(ServeLogLevel::kInfo,
      fmt::format("stopped after {} answered and {} refused inference requests ({} expired in "
                  "the queue, {} stopped when their client left or their deadline passed, {} "
                  "refused with a full queue, {} over a per-request limit)",
                  stats.infer_ok, stats.infer_failed, stats.infer_expired, stats.infer_interrupted,
                  stats.infer_queue_full, stats.infer_over_budget));
#ifdef AVP_WITH_ONNX
  for (const zsl::BatchedNetwork& n : zsl::BatchedNetworks()) {
    log(ServeLogLevel::kInfo,
        fmt::format("network '{}': {} calls in {} runs (at most {} stacked); {} refused, a full "
                    "waiting line; {} stacked runs redone one by one",
                    n.role, n.stats.requests, n.stats.batches, n.stats.largest, n.stats.refused,
                    n.stats.reruns));
  }
#endif
  return Status::Ok();
}

namespace {

int ServeSegmentationAndReport(ServeOptions options) {
  options.log = [](ServeLogLevel level, const std::string& message) {
    if (level == ServeLogLevel::kWarning) {
      spdlog::warn("{}", message);
    } else {
      spdlog::info("{}", message);
    }
  };
  const Status status = RunServeSegmentation(options);
  if (!status.ok()) return Failed("serve segmentation", status);
  return 0;
}

struct ServeCli {
  ServeOptions options;
  std::string backends = "oracle";
  std::string port_file;
  std::string model_server;
  int max_batch = 1;
  int64_t batch_delay_us = 2000;
};

struct ServeModelsCli {
  std::string model_dir, port_file, device = "auto";
  segmentation_service::TensorServerOptions server;
  int intra_op_threads = 0;
  int64_t batch_delay_us = 2000;
  bool verify_sha256 = false;
};

/// avp serve models: the manifest's networks over KServe v2 until SIGINT / SIGTERM.
int ServeModels(const ServeModelsCli& cli) {
#ifdef AVP_WITH_ONNX
  zsl::ModelServiceOptions o;
  o.server = cli.server;
  o.server.batching.max_delay = std::chrono::microseconds(cli.batch_delay_us);
  o.runtime.intra_op_threads = cli.intra_op_threads;
  const Result<zsl::Device> device = zsl::ParseDevice(cli.device);
  if (!device.ok()) return Failed("serve models", device.status());
  o.runtime.device = *device;
  o.verify_sha256 = cli.verify_sha256;
  const ScopedSignalBlock signals;
  Result<zsl::ModelService> service = zsl::ServeModels(cli.model_dir, o);
  if (!service.ok()) return Failed("serve models", service.status());
  spdlog::info("serving the models of {} (KServe v2 / Open Inference Protocol, gRPC) on {}",
               cli.model_dir, service->server->address());
  const std::map<std::string, std::string> batching = service->server->batching();
  for (const zsl::ModelService::Served& m : service->models) {
    const auto how = batching.find(m.name);
    spdlog::info("model '{}': READY ({}, {}); {}", m.name, m.provider,
                 how == batching.end() ? "batching off" : how->second, m.io);
  }
  if (!cli.port_file.empty()) {
    const Status written = io::WriteFileAtomic(
        cli.port_file, fmt::format("{}\n", service->server->port()), "port file");
    if (!written.ok()) return Failed("serve models", written);
  }
  int signal = 0;
  while (signal == 0) signal = signals.Wait(100);
  spdlog::info("{}: shutting down", signal == SIGINT ? "SIGINT" : "SIGTERM");
  service->server->Shutdown(std::chrono::seconds(5));
  if (!cli.port_file.empty()) {
    std::error_code ignored;
    std::filesystem::remove(cli.port_file, ignored);
  }
  const segmentation_service::TensorServerStats stats = service->server->stats();
  spdlog::info("stopped after {} answered and {} refused inference requests", stats.infer_ok,
               stats.infer_failed);
  for (const auto& [name, b] : stats.batching) {
    spdlog::info(
        "model '{}': {} requests in {} runs ({:.2f} per run, at most {}); {} refused, a "
        "full waiting line; {} stacked runs redone one by one",
        name, b.requests, b.batches,
        b.batches == 0 ? 0.0 : static_cast<double>(b.requests) / static_cast<double>(b.batches),
        b.largest, b.refused, b.reruns);
  }
  return 0;
#else
  (void)cli;
  return Failed("serve models",
                FailedPreconditionError("this build has no ONNX Runtime (AVP_WITH_ONNX=OFF)"));
#endif
}

void AddServeSegmentation(CLI::App& serve_cmd, CommandContext& context) {
  auto cli = std::make_shared<ServeCli>();
  segmentation_service::ServerOptions& server = cli->options.server;
  server.host = "0.0.0.0";
  CLI::App* cmd = serve_cmd.add_subcommand(
      "segmentation",
      "The segmentation service: KServe v2 / Open Inference Protocol over gRPC "
      "(docs/segmentation-service.md); runs until SIGINT / SIGTERM");
  cmd->add_option("--port", server.port, "TCP port (0 = pick a free one)")
      ->default_val(server.port);
  cmd->add_option("--backend", cli->backends,
                  "Backends to serve, comma separated, each SPEC (any registered segmenter: `avp "
                  "run --segmenter help`) served as a model of its name, a spec with a scheme by "
                  "its scheme (ywes://DIR as 'ywes'), or NAME=SPEC")
      ->default_val(cli->backends)
      ->type_name("SPEC,...");
  cmd->add_option("--host", server.host, "Address to listen on")->default_val(server.host);
  cmd->add_option("--threads", server.threads, "Worker threads")->default_val(server.threads);
  cmd->add_option("--instances", server.instances_per_model,
                  "Segmenters per (backend, seed) running at once")
      ->default_val(server.instances_per_model);
  cmd->add_option("--seed", server.default_seed, "Segmenter seed of requests that send none")
      ->default_val(server.default_seed);
  cmd->add_option("--max-queue-depth", server.max_queue_depth,
                  "Requests waiting for a worker, all clients together; more are refused at once "
                  "(RESOURCE_EXHAUSTED)")
      ->default_val(server.max_queue_depth);
  cmd->add_option("--max-queued-per-client", server.max_queued_per_client,
                  "Requests of one client (connection) waiting at once; clients are served in turn")
      ->default_val(server.max_queued_per_client);
  cmd->add_option("--max-running-per-client", server.max_running_per_client,
                  "Requests of one client running at once (0: half the worker threads)")
      ->default_val(server.max_running_per_client);
  cmd->add_option("--max-image-pixels", server.max_image_pixels,
                  "Pixels (H x W) of a request's image, from its shape or PNG / JPEG header, "
                  "checked before decoding")
      ->default_val(server.max_image_pixels);
  cmd->add_option("--max-prompt-bytes", server.max_prompt_bytes,
                  "Bytes of a request's prompt (the segmenters' process-wide max_prompt_bytes "
                  "applies too: avp --limit)")
      ->default_val(server.max_prompt_bytes);
  cmd->add_option("--max-prompt-phrases", server.max_prompt_phrases,
                  "Phrases in a request's prompt, duplicates included (and the process-wide "
                  "max_prompt_phrases)")
      ->default_val(server.max_prompt_phrases);
  cmd->add_option("--max-instances", server.max_instances, "Instances in one answer")
      ->default_val(server.max_instances);
  cmd->add_option("--max-cached-seeds", server.max_cached_seeds,
                  "(backend, seed) pairs whose segmenters are kept")
      ->default_val(server.max_cached_seeds);
  cmd->add_option("--port-file", cli->port_file,
                  "Write the bound port to this file once listening");
  cmd->add_option("--model-server", cli->model_server,
                  "grpc://HOST:PORT: ywes and lsam run their networks on this KServe v2 server "
                  "(avp serve models, Triton) instead of in this process (= AVP_ZSL_MODEL_SERVER)");
  cmd->add_option("--max-batch", cli->max_batch,
                  "ywes / lsam in this process: each network with a batch axis is shared by the "
                  "instances and its concurrent calls stacked, up to N rows per run (1 = off; = "
                  "AVP_ZSL_MAX_BATCH; needs --instances > 1)")
      ->default_val(cli->max_batch)
      ->check(CLI::Range(1, 1024));
  cmd->add_option("--batch-delay-us", cli->batch_delay_us,
                  "With --max-batch: how long a network call waits for others, microseconds (= "
                  "AVP_ZSL_BATCH_DELAY_US)")
      ->default_val(cli->batch_delay_us)
      ->check(CLI::Range(int64_t{0}, int64_t{1000000}));
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      // --model-server, --max-batch: the defaults of ywes and lsam (over AVP_ZSL_MODEL_SERVER,
      // AVP_ZSL_MAX_BATCH, AVP_ZSL_BATCH_DELAY_US), which the server builds by spec.
      OptionValues zsl_defaults;
      if (!cli->model_server.empty()) zsl_defaults.emplace_back("model_server", cli->model_server);
      if (cli->max_batch != 1) {
        zsl_defaults.emplace_back("max_batch", std::to_string(cli->max_batch));
        zsl_defaults.emplace_back("batch_delay_us", std::to_string(cli->batch_delay_us));
      }
      const Result<segmentation::SegmenterRegistry> segmenters =
          zsl::WithZslDefaults(context.registries->segmenters, zsl_defaults);
      if (!segmenters.ok()) return Failed("serve segmentation", segmenters.status());
      ServeOptions o = cli->options;
      o.server.segmenters = &*segmenters;
      o.server.backends = SplitCommaList(cli->backends);
      // A name that is no segmenter is a typo, refused before anything listens (a backend whose
      // models are missing is served NOT READY, so that clients learn why).
      for (const std::string& entry : o.server.backends) {
        const segmentation_service::ServedBackend served =
            segmentation_service::ParseServedBackend(entry);
        if (const auto known = segmenters->Get(served.spec); !known.ok()) {
          return Failed("serve segmentation",
                        known.status().WithContext(fmt::format("--backend {}", QuoteText(entry))));
        }
      }
      o.port_file = cli->port_file;
      return ServeSegmentationAndReport(std::move(o));
    });
  });
}

void AddServeModels(CLI::App& serve_cmd, CommandContext& context) {
  auto models = std::make_shared<ServeModelsCli>();
  CLI::App* models_cmd = serve_cmd.add_subcommand(
      "models",
      "Serve the ONNX networks of a model directory (its manifest.json) through ONNX Runtime over "
      "KServe v2 / the Open Inference Protocol (gRPC), each named by its manifest role, for ywes "
      "and lsam's --model-server (docs/zero-shot-models.md)");
  models_cmd->add_option("--model-dir", models->model_dir, "Folder with manifest.json")->required();
  models_cmd->add_option("--port", models->server.port, "TCP port (0 = pick a free one)")
      ->default_val(models->server.port);
  models_cmd->add_option("--host", models->server.host, "Address to listen on")
      ->default_val(models->server.host);
  models_cmd->add_option("--threads", models->server.threads, "Calls handled at once")
      ->default_val(models->server.threads);
  models_cmd
      ->add_option("--intra-op-threads", models->intra_op_threads,
                   "Threads of each ONNX Runtime session (0 = ORT's default)")
      ->default_val(models->intra_op_threads);
  models_cmd->add_option("--device", models->device, "auto, cpu or cuda")
      ->default_val(models->device);
  models_cmd
      ->add_option("--max-dynamic-dim", models->server.max_dynamic_dim,
                   "Largest value of a dimension a model leaves dynamic (boxes, texts)")
      ->default_val(models->server.max_dynamic_dim);
  models_cmd
      ->add_option("--max-batch", models->server.batching.max_batch,
                   "Dynamic batching: the most rows one run stacks, for the models whose inputs "
                   "and outputs all have a dynamic leading axis (1 = off; raise --threads to "
                   "match)")
      ->default_val(models->server.batching.max_batch);
  models_cmd
      ->add_option("--batch-delay-us", models->batch_delay_us,
                   "Dynamic batching: how long a request waits for others, microseconds")
      ->default_val(models->batch_delay_us);
  models_cmd
      ->add_option("--max-batch-queue", models->server.batching.max_queue,
                   "Dynamic batching: requests waiting per model; more are RESOURCE_EXHAUSTED")
      ->default_val(models->server.batching.max_queue);
  models_cmd
      ->add_option("--batch-instances", models->server.batching.instances,
                   "Dynamic batching: batches of one model run at once")
      ->default_val(models->server.batching.instances);
  models_cmd->add_flag("--verify-sha256", models->verify_sha256,
                       "Check every file's sha256 against the manifest first");
  models_cmd->add_option("--port-file", models->port_file,
                         "Write the bound port to this file once listening");
  models_cmd->callback(
      [models, &context] { RunGuarded(context, [&] { return ServeModels(*models); }); });
}

}  // namespace

void AddServeCommand(CLI::App& app, CommandContext& context) {
  CLI::App* serve_cmd = app.add_subcommand("serve", "Network services");
  serve_cmd->require_subcommand(1);
  AddServeSegmentation(*serve_cmd, context);
  AddServeModels(*serve_cmd, context);
}

}  // namespace avp::apps
