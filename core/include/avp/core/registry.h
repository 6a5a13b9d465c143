#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/core/text.h>

namespace avp {

/// The entries a program knows by name, in registration order: what the planner, segmenter and
/// scenario registries share. Built once at start-up, read-only afterwards: const methods may run
/// on several threads at once.
///
/// An Entry has a `std::string name` and three members: `bool Matches(std::string_view spec)`
/// (the name, or a scheme's prefix), `std::string DisplayName()` (how messages list it) and
/// `bool HasFactory()`.
template <typename Entry>
class NamedRegistry {
 public:
  /// `kind` names one entry in messages: "planner" gives "unknown planner 'x' (known: ...)".
  explicit NamedRegistry(std::string kind) : kind_(std::move(kind)) {}

  /// InvalidArgument when the name is empty or taken, or the entry cannot build anything.
  Status Add(Entry entry) {
    if (entry.name.empty()) return InvalidArgumentError("a " + kind_ + " needs a name");
    for (const Entry& e : entries_) {
      if (e.name == entry.name) {
        return InvalidArgumentError(kind_ + " '" + entry.name + "' is already registered");
      }
    }
    if (!entry.HasFactory()) {
      return InvalidArgumentError(kind_ + " '" + entry.name + "' has no factory");
    }
    entries_.push_back(std::move(entry));
    return Status::Ok();
  }
  /// The entry `spec` names; nullptr when none does.
  const Entry* Find(std::string_view spec) const {
    for (const Entry& e : entries_) {
      if (e.Matches(spec)) return &e;
    }
    return nullptr;
  }
  /// The entry, or NotFound "unknown <kind> 'x' (known: a, b, ...)".
  Result<const Entry*> Get(std::string_view spec) const {
    if (const Entry* e = Find(spec)) return e;
    return NotFoundError("unknown " + kind_ + " '" + std::string(spec) + "' (known: " +
                         options_internal::Join(Names(), ", ") + ")" + DidYouMean(spec, Names()));
  }
  /// For entries with options (an AnyOptions `options` member): the defaults of `spec`'s entry,
  /// then `overrides` (KEY=VALUE) applied and validated. Errors: NotFound (unknown name),
  /// InvalidArgument (unknown key, bad or out-of-range value, or options given to an entry
  /// without any).
  Result<AnyOptions> Options(std::string_view spec, const OptionValues& overrides = {}) const {
    AVP_ASSIGN_OR_RETURN(const Entry* entry, Get(spec));
    AnyOptions options = entry->options;
    AVP_RETURN_IF_ERROR(options.SetAll(overrides, kind_ + " '" + std::string(spec) + "'"));
    AVP_RETURN_IF_ERROR(options.Validate());
    return options;
  }
  std::vector<std::string> Names() const {
    std::vector<std::string> names;
    names.reserve(entries_.size());
    for (const Entry& e : entries_) names.push_back(e.DisplayName());
    return names;
  }
  const std::vector<Entry>& entries() const { return entries_; }
  const std::string& kind() const { return kind_; }

 private:
  std::string kind_;
  std::vector<Entry> entries_;
};

/// Adds every entry of `entries` to `registry`. @throws avp::Error naming the entry when a name
/// is taken (registering the built-ins twice is a bug).
template <typename Registry, typename Entry>
void AddAll(Registry& registry, std::vector<Entry> entries) {
  for (Entry& e : entries) {
    const std::string name = e.name;
    const Status s = registry.Add(std::move(e));
    if (!s.ok()) ThrowStatus(s.WithContext(name));
  }
}

}  // namespace avp
