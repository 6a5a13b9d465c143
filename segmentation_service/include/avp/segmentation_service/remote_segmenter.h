#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/segmentation.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/segmentation_service/segmentation_codec.h>

namespace avp::segmentation_service {

/// The default port of `avp serve segmentation` and of the remote:// scheme (Triton's gRPC port).
inline constexpr int kDefaultServicePort = 8001;
/// The model a remote:// spec without one asks for: the same default as `avp run --segmenter`.
inline constexpr std::string_view kDefaultRemoteModel = "oracle";

/// Where and how a RemoteSegmenter talks to a segmentation server.
struct RemoteOptions {
  std::string host = "127.0.0.1";
  int port = kDefaultServicePort;
  std::string model = std::string(kDefaultRemoteModel);
  /// Each call's deadline, seconds (> 0).
  double deadline_s = 30.0;
  /// Largest request or response, both ways.
  int max_message_bytes = 64 << 20;
  /// The `seed` parameter of every request (the run's segmenter seed); not sent when unset, so the
  /// server uses its default.
  std::optional<uint64_t> seed;
  ImageEncoding image = ImageEncoding::kRaw;
  bool send_depth = true;
  bool send_labels = true;
  /// How the answer's masks come back: RLE by default (exact, a few kB per instance instead of
  /// H x W bytes; docs/segmentation-service.md, "Mask formats").
  MaskFormat mask_format = MaskFormat::kRle;

  /// "127.0.0.1:8001" (IPv6 hosts in brackets).
  std::string Address() const;
  /// "remote://127.0.0.1:8001/oracle".
  std::string Spec() const;
  /// Every bad field at once, naming the values.
  Status Validate() const;
};

/// Parses "remote://HOST[:PORT][/MODEL][?key=value&...]": PORT defaults to 8001, MODEL to
/// "oracle"; HOST may be an IPv6 address in brackets. Query keys: deadline_s (seconds), image
/// (raw, png or jpeg), depth and labels (0 or 1), masks (dense, rle or instance_ids: how the
/// answer's masks come back, rle by default). InvalidArgument naming the bad part, e.g.
/// "remote segmenter spec \"remote://h:99999\": port (99999) must be in [1, 65535]".
Result<RemoteOptions> ParseRemoteSpec(std::string_view spec);

/// Whether a model can serve, and why not (the server's stored reason, when it sends one).
struct ModelReadiness {
  bool ready = false;
  std::string reason;
};

/// A model's description as ModelMetadata returns it: versions, platform and tensors.
struct ModelMetadata {
  std::string name;
  std::vector<std::string> versions;
  std::string platform;
  std::vector<TensorSpec> inputs;
  std::vector<TensorSpec> outputs;
};

struct ServerMetadata {
  std::string name;
  std::string version;
  std::vector<std::string> extensions;
};

/// A Segmenter that sends each request to a segmentation server over KServe v2 / OIP gRPC
/// (avp's own `avp serve segmentation`, or Triton / KServe serving a model with the tensors of
/// segmentation_codec.h). Connecting is lazy: construction never fails on a missing server; each
/// call that cannot reach it returns Unavailable naming host:port, and the pipeline ends the
/// episode as a segmenter fault (pipeline/episode.h). Calls have a deadline
/// (RemoteOptions::deadline_s). Segment() and the queries are thread-safe.
class RemoteSegmenter final : public segmentation::Segmenter {
 public:
  /// @throws avp::Error when options.Validate() fails (use ParseRemoteSpec for user input).
  explicit RemoteSegmenter(RemoteOptions options);
  ~RemoteSegmenter() override;
  RemoteSegmenter(const RemoteSegmenter&) = delete;
  RemoteSegmenter& operator=(const RemoteSegmenter&) = delete;

  /// The spec, "remote://host:port/model".
  std::string_view name() const override;
  /// Encodes, calls ModelInfer, decodes. Errors: the server's INVALID_ARGUMENT / NOT_FOUND /
  /// FAILED_PRECONDITION / RESOURCE_EXHAUSTED as InvalidArgument / NotFound / FailedPrecondition
  /// / ResourceExhausted; a server that cannot be reached as Unavailable; a deadline that passed
  /// as DeadlineExceeded; CANCELLED as Cancelled; other transport failures as IoError; all
  /// prefixed with the spec and naming host:port.
  Result<Segmentation> Segment(const segmentation::SegmentationRequest& request) override;

  Result<bool> ServerLive();
  Result<bool> ServerReady();
  /// Readiness of options().model.
  Result<ModelReadiness> GetModelReadiness();
  Result<ModelMetadata> GetModelMetadata();
  Result<ServerMetadata> GetServerMetadata();

  const RemoteOptions& options() const { return options_; }

 private:
  struct Impl;
  RemoteOptions options_;
  std::string spec_;
  std::unique_ptr<Impl> impl_;
};

/// Registers the "remote://" scheme with `registry`, so that every command and config accepts
/// "remote://host:port[/model]". The factory parses the spec (its settings are in the spec's
/// query, ParseRemoteSpec) and sends the run's segmenter seed as the `seed` parameter.
/// @throws avp::Error if the scheme is already registered.
void RegisterRemoteSegmenter(segmentation::SegmenterRegistry& registry);

}  // namespace avp::segmentation_service
