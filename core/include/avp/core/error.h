#pragma once

#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <fmt/ostream.h>

namespace avp {

/// Thrown for violated preconditions at API boundaries. The message names the failed condition and
/// prints every value passed to AVP_THROW_UNLESS, e.g.
///   "requirement failed: fx > 0 (fx = -1, width = 640) at core/src/camera.cpp:42".
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace internal {

/// Splits "a, f(b, c), d" into {"a", "f(b, c)", "d"} (top-level commas only).
std::vector<std::string> SplitMacroArgNames(std::string_view names);

template <typename T>
std::string FormatValue(const T& value) {
  if constexpr (fmt::is_formattable<T>::value) {
    return fmt::format("{}", value);
  } else {
    std::ostringstream os;
    os << value;
    return os.str();
  }
}

template <typename... Ts>
std::string FormatNamedValues(std::string_view names, const Ts&... values) {
  if constexpr (sizeof...(Ts) == 0) {
    return {};
  } else {
    const std::vector<std::string> split = SplitMacroArgNames(names);
    const std::vector<std::string> formatted = {FormatValue(values)...};
    std::string out = " (";
    for (size_t i = 0; i < formatted.size(); ++i) {
      if (i > 0) out += ", ";
      out += (i < split.size() ? split[i] : std::string("?")) + " = " + formatted[i];
    }
    return out + ")";
  }
}

[[noreturn]] void ThrowRequirementFailed(std::string_view condition, std::string values,
                                         const char* file, int line);

}  // namespace internal
}  // namespace avp

/// Throws avp::Error unless `cond` holds; the message shows `cond` and the named values.
///   AVP_THROW_UNLESS(width > 0, width, height);
#define AVP_THROW_UNLESS(cond, ...)                                                           \
  do {                                                                                        \
    if (!(cond)) {                                                                            \
      ::avp::internal::ThrowRequirementFailed(                                                \
          #cond, ::avp::internal::FormatNamedValues(#__VA_ARGS__ __VA_OPT__(, ) __VA_ARGS__), \
          __FILE__, __LINE__);                                                                \
    }                                                                                         \
  } while (false)
