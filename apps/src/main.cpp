// The `avp` command line: each command lives in its own file (apps/src/<name>_command.cpp) and
// adds itself here; the registries of everything a user picks by name are built once.
#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <avp/core/text.h>
#include <avp/experiment/registries.h>
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

/// The options of `command` and of every command above it (those fall through), long names.
std::vector<std::string> OptionNames(const CLI::App* command) {
  std::vector<std::string> names;
  for (const CLI::App* c = command; c != nullptr; c = c->get_parent()) {
    for (const CLI::Option* o : c->get_options()) {
      for (const std::string& n : o->get_lnames()) names.push_back("--" + n);
    }
  }
  return names;
}

/// The commands (`avp bench`, `avp map build`) that have an option named `name`.
std::vector<std::string> CommandsWithOption(CLI::App& app, const std::string& name,
                                            const std::string& prefix = "avp") {
  std::vector<std::string> found;
  for (CLI::App* c : app.get_subcommands([](CLI::App*) { return true; })) {
    const std::string path = prefix + " " + c->get_name();
    for (const CLI::Option* o : c->get_options()) {
      const std::vector<std::string>& own = o->get_lnames();
      if (std::find(own.begin(), own.end(), name.substr(2)) != own.end()) found.push_back(path);
    }
    for (const std::string& deeper : CommandsWithOption(*c, name, path)) found.push_back(deeper);
  }
  return found;
}

/// "avp map build": the words of `command`'s path.
std::string CommandPath(const CLI::App* command) {
  std::string path;
  for (const CLI::App* c = command; c != nullptr && c->get_parent() != nullptr;
       c = c->get_parent()) {
    path = " " + c->get_name() + path;
  }
  return "avp" + path;
}

/// Words the command line did not expect, in the order given: the first unknown option is named
/// with the nearest option of the command, or the commands that have it ("--seeds is avp bench's");
/// else the stray values.
int ReportExtras(CLI::App& app, CLI::App* current) {
  const std::vector<std::string> extras = app.remaining(true);
  const std::string path = CommandPath(current);
  for (const std::string& word : extras) {
    if (!word.starts_with("--")) continue;
    const std::string name = word.substr(0, word.find('='));
    std::string hint = avp::DidYouMean(name, OptionNames(current));
    const std::vector<std::string> owners = CommandsWithOption(app, name);
    if (!owners.empty()) {
      hint += fmt::format(" ({} is an option of {})", name, fmt::join(owners, ", "));
    }
    std::fprintf(stderr, "%s: unknown option %s%s; `%s --help` lists its options\n", path.c_str(),
                 avp::QuoteText(name).c_str(), hint.c_str(), path.c_str());
    return 2;
  }
  std::vector<std::string> quoted;
  for (const std::string& w : extras) quoted.push_back(avp::QuoteText(w));
  std::fprintf(stderr,
               "%s: unexpected argument%s %s (a value with spaces needs quotes; `%s --help` lists "
               "the options)\n",
               path.c_str(), extras.size() == 1 ? "" : "s",
               fmt::format("{}", fmt::join(quoted, " ")).c_str(), path.c_str());
  return 2;
}

/// A parse error, with the command a misspelt word most likely meant ("avp rendr": did you mean
/// 'render'?) where there is one, the option an unknown one most likely meant; else CLI11's
/// message.
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
  if (dynamic_cast<const CLI::RequiredError*>(&e) != nullptr &&
      current->get_subcommands().empty() && !names.empty() &&
      current->get_require_subcommand_min() > 0) {
    std::fprintf(stderr, "%s: a command is required: %s (`avp help%s COMMAND`)\n",
                 CommandPath(current).c_str(), CLI::detail::join(names, ", ").c_str(),
                 current == &app ? "" : (" " + current->get_name()).c_str());
    return 2;
  }
  if (dynamic_cast<const CLI::ExtrasError*>(&e) != nullptr && !app.remaining(true).empty()) {
    return ReportExtras(app, current);
  }
  return app.exit(e);
}

/// Whether `option` takes a list in `command` (or an option group of it): a vector option split on
/// commas (render --joints), or one whose type name says so ("NAME,...": bench --planners, serve
/// segmentation --backend). Such an option's space-separated values ("--joints 0 -70 60": the
/// words after it up to the next option; negative numbers are values) are read as the commas are.
bool IsListOption(const CLI::App* command, const std::string& option) {
  if (command == nullptr || !option.starts_with("--")) return false;
  const CLI::Option* o = command->get_option_no_throw(option);
  return o != nullptr && (o->get_delimiter() == ',' || o->get_type_name().ends_with(",..."));
}

/// A word that is a value after a list option: not an option (a negative number is a value), not
/// a command's name.
bool IsListValue(const std::string& word, const std::vector<std::string>& commands) {
  if (word.empty()) return true;
  if (word[0] == '-') {
    return word.size() > 1 &&
           (std::isdigit(static_cast<unsigned char>(word[1])) != 0 || word[1] == '.');
  }
  return std::find(commands.begin(), commands.end(), word) == commands.end();
}

/// The command line with each list option's space-separated values joined by commas; `app`
/// tells the commands (followed as they are named) and their list options.
std::vector<std::string> JoinListArguments(int argc, char** argv, CLI::App& app,
                                           const std::vector<std::string>& commands) {
  std::vector<std::string> out;
  CLI::App* command = &app;  // the deepest command named so far
  for (int i = 0; i < argc; ++i) {
    const std::string word = argv[i];
    out.push_back(word);
    if (i > 0 && !word.starts_with("-")) {
      for (CLI::App* sub : command->get_subcommands([](CLI::App*) { return true; })) {
        if (sub->get_name() == word) command = sub;
      }
      continue;
    }
    if (!IsListOption(command, word) || i + 1 >= argc) continue;
    std::string joined = argv[++i];
    while (i + 1 < argc && IsListValue(argv[i + 1], commands)) {
      joined += "," + std::string(argv[++i]);
    }
    out.push_back(joined);
  }
  return out;
}

/// Every command's name, at every depth (never a list value).
std::vector<std::string> AllCommandNames(CLI::App& app) {
  std::vector<std::string> names;
  for (CLI::App* c : app.get_subcommands([](CLI::App*) { return true; })) {
    names.push_back(c->get_name());
    for (const std::string& n : AllCommandNames(*c)) names.push_back(n);
  }
  return names;
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
  avp::zsl::RegisterProgramSegmenters(registries.segmenters);

  CLI::App app{
      "avp: active vision for agricultural robots (simulated RGB-D arm, semantic mapping, "
      "next-best-view planning)"};
  app.require_subcommand(1);
  // The global options (--limit) anywhere on the line, after the command too.
  app.fallthrough();
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
  const std::vector<std::string> words = JoinListArguments(argc, argv, app, AllCommandNames(app));
  std::vector<char*> args;
  for (const std::string& w : words) args.push_back(const_cast<char*>(w.c_str()));
  try {
    app.parse(static_cast<int>(args.size()), args.data());
  } catch (const CLI::ParseError& e) {
    return ReportParseError(app, e, static_cast<int>(args.size()), args.data());
  }
  return context.exit_code;
}
