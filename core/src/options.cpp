#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <string>

#include <fmt/format.h>

#include <avp/core/options.h>

namespace avp {

bool ValueRange::Contains(double v) const {
  if (lo_open ? !(v > lo) : !(v >= lo)) return false;
  if (hi_open ? !(v < hi) : !(v <= hi)) return false;
  return true;
}

std::string ValueRange::ToString() const {
  const bool has_lo = std::isfinite(lo);
  const bool has_hi = std::isfinite(hi);
  if (has_lo && has_hi) {
    return fmt::format("{}{}, {}{}", lo_open ? '(' : '[', options_internal::FormatReal(lo),
                       options_internal::FormatReal(hi), hi_open ? ')' : ']');
  }
  if (has_lo) return fmt::format("{} {}", lo_open ? ">" : ">=", options_internal::FormatReal(lo));
  if (has_hi) return fmt::format("{} {}", hi_open ? "<" : "<=", options_internal::FormatReal(hi));
  return "";
}

std::string ValueRange::Requirement() const {
  const std::string range = ToString();
  if (range.empty()) return "a number";
  return std::isfinite(lo) && std::isfinite(hi) ? "in " + range : range;
}

namespace options_internal {

std::string FormatReal(double v) { return fmt::format("{}", v); }
std::string FormatFloat(float v) { return fmt::format("{}", v); }

std::optional<double> ParseReal(std::string_view text) {
  const std::string t(text);
  if (t.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(t.c_str(), &end);
  // ERANGE with a finite result is an underflow ("1e-320"): the nearest double (subnormal or 0)
  // is that number; an overflow ("1e400") is infinite, refused.
  if (end != t.c_str() + t.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<int64_t> ParseInteger(std::string_view text) {
  int64_t v = 0;
  const char* first = text.data();
  const char* last = text.data() + text.size();
  if (!text.empty() && text.front() == '+') ++first;
  const auto [ptr, ec] = std::from_chars(first, last, v);
  if (ec == std::errc() && ptr == last && first != last) return v;
  // A whole number written as a real ("2.0", "1e3").
  const std::optional<double> d = ParseReal(text);
  if (!d || *d != std::floor(*d) || std::abs(*d) > 9.0e15) return std::nullopt;
  return static_cast<int64_t>(*d);
}

std::optional<uint64_t> ParseUnsigned(std::string_view text) {
  // No sign at all: strtoull would wrap "-1" to 2^64 - 1.
  if (text.empty() || text.front() == '-' || text.front() == '+') return std::nullopt;
  uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec == std::errc() && ptr == text.data() + text.size()) return v;
  return std::nullopt;
}

std::optional<bool> ParseFlag(std::string_view text) {
  if (text == "true") return true;
  if (text == "false") return false;
  return std::nullopt;
}

std::vector<std::string> SplitList(std::string_view text) {
  std::vector<std::string> items;
  size_t start = 0;
  while (start <= text.size()) {
    size_t end = text.find(',', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view item = text.substr(start, end - start);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    if (!item.empty()) items.emplace_back(item);
    start = end + 1;
  }
  return items;
}

std::string Join(const std::vector<std::string>& items, std::string_view separator) {
  std::string out;
  for (const std::string& item : items) {
    if (!out.empty()) out += separator;
    out += item;
  }
  return out;
}

}  // namespace options_internal

Status AnyOptions::Set(std::string_view key, std::string_view value, std::string_view component) {
  if (impl_ == nullptr || impl_->Keys().empty()) {
    return InvalidArgumentError(fmt::format("{} has no options (given: {} = {})",
                                            component.empty() ? "this component" : component, key,
                                            value));
  }
  return impl_->Set(key, value);
}

Status AnyOptions::SetAll(const OptionValues& values, std::string_view component) {
  for (const auto& [key, value] : values) AVP_RETURN_IF_ERROR(Set(key, value, component));
  return Status::Ok();
}

std::string FormatOptionHelp(const std::vector<OptionInfo>& info, std::string_view indent) {
  // Three aligned columns: KEY=DEFAULT, [unit, range], meaning. A cell wider than its column's
  // cap (a long default list) keeps its line and the next columns start on the line below, so
  // that one long entry does not push every description far to the right.
  constexpr size_t kMaxKeyColumn = 40, kMaxBoundsColumn = 30;
  std::vector<std::string> keys, bounds;
  size_t key_w = 0, bounds_w = 0;
  for (const OptionInfo& i : info) {
    keys.push_back(i.key + "=" + i.default_value);
    std::string b = i.unit;
    if (!i.range.empty()) b += (b.empty() ? "" : ", ") + i.range;
    bounds.push_back(b.empty() ? std::string() : "[" + b + "]");
    if (keys.back().size() <= kMaxKeyColumn) key_w = std::max(key_w, keys.back().size());
    if (bounds.back().size() <= kMaxBoundsColumn)
      bounds_w = std::max(bounds_w, bounds.back().size());
  }
  std::string out;
  for (size_t k = 0; k < info.size(); ++k) {
    std::string line = fmt::format("{}{:<{}}  ", indent, keys[k], key_w);
    if (keys[k].size() > key_w) {
      out += fmt::format("{}{}\n", indent, keys[k]);
      line = fmt::format("{}{:<{}}  ", indent, "", key_w);
    }
    line += fmt::format("{:<{}}  {}", bounds[k], bounds_w, info[k].doc);
    while (!line.empty() && line.back() == ' ') line.pop_back();
    out += line + "\n";
  }
  return out;
}

Result<OptionValues> ParseKeyValues(const std::vector<std::string>& items, std::string_view what) {
  OptionValues out;
  for (const std::string& item : items) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      return InvalidArgumentError(fmt::format("{} '{}' must be KEY=VALUE", what, item));
    }
    out.emplace_back(item.substr(0, eq), item.substr(eq + 1));
  }
  return out;
}

}  // namespace avp
