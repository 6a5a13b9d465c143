// The `avp` command line: each command lives in its own file (apps/src/<name>_command.cpp) and
// adds itself here; the registries of everything a user picks by name are built once.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <avp/core/text.h>
#include <avp/experiment/registries.h>
#include <avp/segmentation_service/remote_segmenter.h>
#include <avp/zsl/register.h>

#include "commands.h"
#include "limits_cli.h"

namespace {

/// The names of `app`'s commands.
std::vector<std::string> CommandNames(CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* c : app.get_subcommands([](CLI::App*) { return true; })) {
    names.push_back(c->get_name());
  }
  return names;
}

/// The command `app` was parsing when it failed: the last one given.
CLI::App* DeepestCommand(CLI::App& app) {
  CLI::App* current = &app;
  for (std::vector<CLI::App*> given = current->get_subcommands(); !given.empty();
       given = current->get_subcommands()) {
    current = given.front();
  }
  return current;
}

/// A parse error, with the command a misspelt word most likely meant ("avp rendr": did you mean
/// 'render'?) where there is one; else CLI11's message.
int ReportParseError(CLI::App& app, const CLI::ParseError& e, int argc, char** argv) {
  CLI::App* current = DeepestCommand(app);
  const std::vector<std::string> names = CommandNames(*current);
  for (int i = 1; i < argc && !names.empty(); ++i) {
    const std::string word = argv[i];
    if (word.empty() || word[0] == '-' ||
        std::find(names.begin(), names.end(), word) != names.end()) {
      continue;
    }
    const std::string nearest = avp::NearestName(word, names);
    if (nearest.empty()) continue;
    std::fprintf(stderr, "avp: unknown command %s; did you mean '%s'? (commands: %s; avp help%s)\n",
                 avp::QuoteText(word).c_str(), nearest.c_str(),
                 CLI::detail::join(names, ", ").c_str(),
                 current == &app ? "" : (" " + current->get_name()).c_str());
    return 2;
  }
  return app.exit(e);
}

/// `avp help [COMMAND [SUBCOMMAND]]`: the help of that command (misspelt names get a suggestion).
void AddHelpCommand(CLI::App& app, avp::apps::CommandContext& context) {
  auto words = std::make_shared<std::vector<std::string>>();
  CLI::App* cmd = app.add_subcommand("help", "Help on avp or on one command: avp help map build");
  cmd->add_option("command", *words, "A command and its subcommands");
  cmd->callback([&app, words, &context] {
    CLI::App* target = &app;
    for (const std::string& w : *words) {
      CLI::App* next = nullptr;
      for (CLI::App* c : target->get_subcommands([](CLI::App*) { return true; })) {
        if (c->get_name() == w) next = c;
      }
      if (next == nullptr) {
        std::fprintf(stderr, "avp help: unknown command %s (commands: %s)%s\n",
                     avp::QuoteText(w).c_str(),
                     CLI::detail::join(CommandNames(*target), ", ").c_str(),
                     avp::DidYouMean(w, CommandNames(*target)).c_str());
        context.exit_code = 2;
        return;
      }
      target = next;
    }
    // The formatter, not App::help(): that prints the selected command's help (here: help's).
    std::fputs(target->get_formatter()
                   ->make_help(target, target->get_name(), CLI::AppFormatMode::Normal)
                   .c_str(),
               stdout);
  });
}

}  // namespace

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
  AddHelpCommand(app, context);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return ReportParseError(app, e, argc, argv);
  }
  return context.exit_code;
}
