#include "cli_common.h"

#include <exception>

#include <spdlog/spdlog.h>

#include <avp/core/error.h>

namespace avp::apps {

void RunGuarded(CommandContext& context, const std::function<int()>& command) {
  try {
    context.exit_code = command();
  } catch (const Error& e) {
    spdlog::error("{}", e.what());
    context.exit_code = 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    context.exit_code = 2;
  }
}

int Failed(std::string_view command, const Status& status) {
  spdlog::error("{} failed: {}", command, status.ToString());
  return 1;
}

std::vector<std::string> SplitCommaList(std::string_view text) {
  return options_internal::SplitList(text);
}

CLI::Option* AddKeyValueOption(CLI::App& cmd, const std::string& name,
                               std::vector<std::string>& values, const std::string& description) {
  return cmd.add_option(name, values, description)->type_name("KEY=VALUE");
}

}  // namespace avp::apps
