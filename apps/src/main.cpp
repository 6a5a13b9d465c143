// The `avp` command line: each command lives in its own file (apps/src/<name>_command.cpp) and
// adds itself here; the registries of everything a user picks by name are built once.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <avp/experiment/registries.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/zsl/register.h>

#include "commands.h"
#include "limits_cli.h"

int main(int argc, char** argv) {
  avp::experiment::Registries registries = avp::experiment::BuiltinRegistries();
  // Every command and config also accepts remote://host:port[/model] as a segmenter, and ywes /
  // lsam (models from AVP_ZSL_MODEL_DIR), ywes://DIR, lsam://DIR.
  avp::segmentation_service::RegisterRemoteSegmenter(registries.segmenters);
  avp::zsl::RegisterZslSegmenters(registries.segmenters);

  CLI::App app{
      "avp: active vision for agricultural robots (simulated RGB-D arm, semantic mapping, "
      "next-best-view planning)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "avp 0.1.0");
  // The limits on what input controls: AVP_LIMITS, then --limit over it, before any command.
  avp::apps::RegisterKnownLimits();
  if (const avp::Status s = avp::apps::ApplyLimitsFromEnvironment(); !s.ok()) {
    spdlog::error("{}", s.ToString());
    return 1;
  }
  avp::apps::AddLimitOption(app);
  avp::apps::CommandContext context{&registries, 0};
  for (const auto add :
       {avp::apps::AddScenesCommand, avp::apps::AddSceneCommand, avp::apps::AddRenderCommand,
        avp::apps::AddMapCommand, avp::apps::AddRunCommand, avp::apps::AddReplayCommand,
        avp::apps::AddBenchCommand, avp::apps::AddServeCommand, avp::apps::AddSegmentCommand,
        avp::apps::AddLimitsCommand}) {
    add(app, context);
  }
#ifdef AVP_WITH_ROS2
  avp::apps::AddLiveCommand(app, context);
  avp::apps::AddSimCommand(app, context);
#endif
  CLI11_PARSE(app, argc, argv);
  return context.exit_code;
}
