#include <fmt/format.h>

#include <avp/core/limits.h>

namespace avp {

Status ExceedsLimit(std::string_view what, uint64_t amount, std::string_view limit_name,
                    uint64_t limit, std::string_view how_to_raise) {
  std::string message =
      fmt::format("{} ({}) exceeds the limit {} = {}", what, amount, limit_name, limit);
  if (!how_to_raise.empty()) message += fmt::format("; {}", how_to_raise);
  return ResourceExhaustedError(std::move(message));
}

}  // namespace avp
