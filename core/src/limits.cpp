#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/limits.h>
#include <avp/core/text.h>

namespace avp {

struct Limit::Entry {
  std::string name;
  uint64_t default_value = 0;
  std::string unit;
  std::string doc;
  std::atomic<uint64_t> value{0};
};

namespace {

struct Registry {
  std::mutex mutex;
  std::map<std::string, std::unique_ptr<Limit::Entry>, std::less<>> entries;
};

Registry& GetRegistry() {
  static Registry* registry = new Registry;  // never destroyed: limits outlive static teardown
  return *registry;
}

bool ValidName(std::string_view name) {
  if (name.empty()) return false;
  for (const char c : name) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_')) return false;
  }
  return true;
}

std::vector<std::string> LimitNames(const Registry& r) {
  std::vector<std::string> names;
  for (const auto& [name, entry] : r.entries) names.push_back(name);
  return names;
}

std::string KnownNames(const Registry& r) {
  std::string out;
  for (const auto& [name, entry] : r.entries) {
    if (!out.empty()) out += ", ";
    out += name;
  }
  return out.empty() ? "none" : out;
}

}  // namespace

Status ExceedsLimit(std::string_view what, uint64_t amount, std::string_view limit_name,
                    uint64_t limit, std::string_view how_to_raise) {
  std::string message =
      fmt::format("{} ({}) exceeds the limit {} = {}", what, amount, limit_name, limit);
  if (!how_to_raise.empty()) message += fmt::format("; {}", how_to_raise);
  return ResourceExhaustedError(std::move(message));
}

Limit::Limit(std::string_view name, uint64_t default_value, std::string_view unit,
             std::string_view doc) {
  if (!ValidName(name) || default_value < 1) {
    throw Error(
        fmt::format("limit {} needs a name of [a-z0-9_]+ and a default >= 1", QuoteText(name)));
  }
  Registry& r = GetRegistry();
  const std::lock_guard<std::mutex> lock(r.mutex);
  auto entry = std::make_unique<Entry>();
  entry->name = std::string(name);
  entry->default_value = default_value;
  entry->unit = std::string(unit);
  entry->doc = std::string(doc);
  entry->value.store(default_value);
  const auto [it, inserted] = r.entries.emplace(std::string(name), std::move(entry));
  if (!inserted) throw Error(fmt::format("limit '{}' registered twice", name));
  entry_ = it->second.get();
}

const std::string& Limit::name() const { return entry_->name; }

uint64_t Limit::value() const { return entry_->value.load(std::memory_order_relaxed); }

Status Limit::Check(std::string_view what, uint64_t amount) const {
  const uint64_t limit = value();
  if (amount <= limit) return Status::Ok();
  return ExceedsLimit(what, amount, entry_->name, limit,
                      fmt::format("raise it with --limit {}=N (docs/limits.md)", entry_->name));
}

Status SetLimit(std::string_view name, uint64_t value) {
  Registry& r = GetRegistry();
  const std::lock_guard<std::mutex> lock(r.mutex);
  const auto it = r.entries.find(name);
  if (it == r.entries.end()) {
    return NotFoundError(fmt::format("unknown limit {} (known: {}){}", QuoteText(name),
                                     KnownNames(r), DidYouMean(name, LimitNames(r))));
  }
  if (value == 0) {
    return InvalidArgumentError(fmt::format("limit {} must be >= 1", it->first));
  }
  it->second->value.store(value);
  return Status::Ok();
}

Status SetLimits(std::string_view assignments) {
  size_t start = 0;
  while (start <= assignments.size()) {
    size_t end = assignments.find(',', start);
    if (end == std::string_view::npos) end = assignments.size();
    std::string_view item = assignments.substr(start, end - start);
    while (!item.empty() && item.front() == ' ') item.remove_prefix(1);
    while (!item.empty() && item.back() == ' ') item.remove_suffix(1);
    if (!item.empty()) {
      const size_t eq = item.find('=');
      if (eq == std::string_view::npos) {
        return InvalidArgumentError(fmt::format(
            "limit {} must be NAME=VALUE (e.g. max_image_pixels=400000000)", QuoteText(item)));
      }
      const std::string_view name = item.substr(0, eq);
      const std::string_view text = item.substr(eq + 1);
      uint64_t value = 0;
      bool ok = !text.empty() && text.size() <= 19;
      for (const char c : text) {
        if (c < '0' || c > '9') ok = false;
      }
      if (ok) {
        for (const char c : text) value = value * 10 + static_cast<uint64_t>(c - '0');
      }
      if (!ok || value == 0) {
        return InvalidArgumentError(
            fmt::format("limit {}: value {} must be a whole number in [1, 9999999999999999999]",
                        QuoteText(name), QuoteText(text)));
      }
      AVP_RETURN_IF_ERROR(SetLimit(name, value));
    }
    start = end + 1;
  }
  return Status::Ok();
}

std::vector<LimitInfo> RegisteredLimits() {
  Registry& r = GetRegistry();
  const std::lock_guard<std::mutex> lock(r.mutex);
  std::vector<LimitInfo> out;
  for (const auto& [name, e] : r.entries) {
    out.push_back({e->name, e->value.load(), e->default_value, e->unit, e->doc});
  }
  return out;
}

ScopedLimit::ScopedLimit(const Limit& limit, uint64_t value)
    : name_(limit.name()), previous_(limit.value()) {
  const Status s = SetLimit(name_, value);
  if (!s.ok()) throw Error(s.ToString());
}

ScopedLimit::~ScopedLimit() { (void)SetLimit(name_, previous_); }

}  // namespace avp
