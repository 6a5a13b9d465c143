#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <avp/segmentation/segment_image.h>
#include <avp/zsl/register.h>

#include "cli_common.h"

namespace avp::apps {

using segmentation::SegmentOptions;

namespace {

int SegmentAndReport(const SegmentOptions& options,
                     const segmentation::SegmenterRegistry& segmenters) {
  const auto result = segmentation::SegmentImageToFolder(options, segmenters);
  if (!result.ok()) return Failed("segment", result.status());
  std::fputs(segmentation::FormatSegmentSummary(*result).c_str(), stdout);
  std::printf("wrote %zu files to %s:\n", result->files.size(), options.out_dir.string().c_str());
  for (const auto& f : result->files) std::printf("  %s\n", f.string().c_str());
  return 0;
}

struct SegmentCli {
  SegmentOptions options;
  std::string image, models, model_server, out = SegmentOptions{}.out_dir.string();
  std::vector<std::string> segmenter_options;
};

}  // namespace

void AddSegmentCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<SegmentCli>();
  SegmentOptions& s = cli->options;
  CLI::App* cmd = app.add_subcommand(
      "segment",
      "Segment one image from a text prompt; writes overlay.png and instances.json "
      "(docs/zero-shot-models.md)");
  cmd->add_option("--image", cli->image, "JPEG or PNG image")->required();
  cmd->add_option("--prompt", s.prompt, "Comma-separated phrases")->default_val(s.prompt);
  cmd->add_option("--backend", s.backend,
                  "Segmenter: ywes, lsam (models from --models or AVP_ZSL_MODEL_DIR), "
                  "ywes://DIR, lsam://DIR, any other registered one (`avp run --segmenter "
                  "help`), remote://host:port")
      ->default_val(s.backend);
  cmd->add_option("--models", cli->models,
                  "Model directory of ywes / lsam (default: AVP_ZSL_MODEL_DIR)");
  cmd->add_option("--model-server", cli->model_server,
                  "grpc://HOST:PORT: ywes / lsam run their networks on this KServe v2 server "
                  "(avp serve models, Triton) instead of in this process (= "
                  "AVP_ZSL_MODEL_SERVER)");
  AddKeyValueOption(*cmd, "--segmenter-option", cli->segmenter_options,
                    "Segmenter option over its defaults (repeatable)");
  AddNumberOption(*cmd, "--threshold", s.threshold, 0.0f, 1.0f,
                  "Drop instances scoring below this");
  AddNumberOption(*cmd, "--seed", s.seed, decltype(s.seed){0}, MaxOf<decltype(s.seed)>(),
                  "Segmenter seed (noisy segmenters only)");
  cmd->add_option("--out", cli->out, "Output folder")->default_val(cli->out);
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      SegmentOptions o = cli->options;
      o.image = cli->image;
      o.models = cli->models;
      o.out_dir = cli->out;
      const Result<OptionValues> values =
          ParseKeyValues(cli->segmenter_options, "segmenter option");
      if (!values.ok()) return Failed("segment", values.status());
      o.segmenter_options = *values;
      if (cli->model_server.empty()) return SegmentAndReport(o, context.registries->segmenters);
      // --model-server: the default model_server of ywes and lsam (over AVP_ZSL_MODEL_SERVER).
      const Result<segmentation::SegmenterRegistry> segmenters = zsl::WithZslDefaults(
          context.registries->segmenters, {{"model_server", cli->model_server}});
      if (!segmenters.ok()) return Failed("segment", segmenters.status());
      return SegmentAndReport(o, *segmenters);
    });
  });
}

}  // namespace avp::apps
