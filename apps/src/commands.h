#pragma once

#include <avp/experiment/registries.h>

namespace CLI {
class App;
}  // namespace CLI

namespace avp::apps {

/// What the commands share: the program's registries (built once in main) and the exit code of
/// the command that ran (0 done, 1 failed, 2 unexpected error).
struct CommandContext {
  const experiment::Registries* registries = nullptr;
  int exit_code = 0;
};

/// Each adds its subcommand to `app` with its options; when the subcommand is given, its callback
/// runs it and sets context.exit_code. One file per command (apps/src/<name>_command.cpp).
void AddScenesCommand(CLI::App& app, CommandContext& context);
/// avp scene check FILE: what the loader makes of a scene file (apps/src/scene_command.cpp).
void AddSceneCommand(CLI::App& app, CommandContext& context);
void AddRenderCommand(CLI::App& app, CommandContext& context);
void AddMapCommand(CLI::App& app, CommandContext& context);
void AddRunCommand(CLI::App& app, CommandContext& context);
void AddBenchCommand(CLI::App& app, CommandContext& context);
/// avp replay BAG: segmentation, mapping and evaluation over an MCAP recording
/// (apps/src/replay_command.cpp).
void AddReplayCommand(CLI::App& app, CommandContext& context);
void AddServeCommand(CLI::App& app, CommandContext& context);
void AddSegmentCommand(CLI::App& app, CommandContext& context);
/// avp limits: every process-wide limit (name, value, default, unit, what it bounds).
void AddLimitsCommand(CLI::App& app, CommandContext& context);
/// ROS 2 commands (built with AVP_WITH_ROS2): avp live, avp sim ros2.
void AddLiveCommand(CLI::App& app, CommandContext& context);
void AddSimCommand(CLI::App& app, CommandContext& context);

}  // namespace avp::apps
