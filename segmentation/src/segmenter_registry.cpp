#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/segmentation/color_segmenter.h>
#include <avp/segmentation/oracle_segmenter.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::segmentation {

bool SegmenterEntry::is_scheme() const {
  return name.size() >= 3 && name.compare(name.size() - 3, 3, "://") == 0;
}

Status SegmenterRegistry::Add(SegmenterEntry entry) {
  if (entry.name.empty()) return InvalidArgumentError("a segmenter needs a name");
  for (const SegmenterEntry& e : entries_) {
    if (e.name == entry.name) {
      return InvalidArgumentError(fmt::format("segmenter '{}' is already registered", entry.name));
    }
  }
  if (!entry.make) {
    return InvalidArgumentError(fmt::format("segmenter '{}' has no factory", entry.name));
  }
  entries_.push_back(std::move(entry));
  return Status::Ok();
}

const SegmenterEntry* SegmenterRegistry::Find(std::string_view spec) const {
  for (const SegmenterEntry& e : entries_) {
    if (e.name == spec || (e.is_scheme() && spec.substr(0, e.name.size()) == e.name)) return &e;
  }
  return nullptr;
}

Result<const SegmenterEntry*> SegmenterRegistry::Get(std::string_view spec) const {
  if (const SegmenterEntry* e = Find(spec)) return e;
  return NotFoundError(
      fmt::format("unknown segmenter '{}' (known: {})", spec, fmt::join(Names(), ", ")));
}

std::vector<std::string> SegmenterRegistry::Names() const {
  std::vector<std::string> names;
  for (const SegmenterEntry& e : entries_) names.push_back(e.is_scheme() ? e.name + "..." : e.name);
  return names;
}

Result<AnyOptions> SegmenterRegistry::Options(std::string_view spec,
                                              const OptionValues& overrides) const {
  AVP_ASSIGN_OR_RETURN(const SegmenterEntry* entry, Get(spec));
  AnyOptions options = entry->options;
  AVP_RETURN_IF_ERROR(options.SetAll(overrides, fmt::format("segmenter '{}'", spec)));
  AVP_RETURN_IF_ERROR(options.Validate());
  return options;
}

Result<std::unique_ptr<Segmenter>> SegmenterRegistry::Make(std::string_view spec,
                                                           const AnyOptions& options,
                                                           const SegmenterContext& context) const {
  AVP_ASSIGN_OR_RETURN(const SegmenterEntry* entry, Get(spec));
  AVP_RETURN_IF_ERROR(options.Validate());
  return entry->make(spec, options, context);
}

Result<std::unique_ptr<Segmenter>> SegmenterRegistry::Make(std::string_view spec,
                                                           uint64_t seed) const {
  AVP_ASSIGN_OR_RETURN(const SegmenterEntry* entry, Get(spec));
  return Make(spec, entry->options, SegmenterContext{seed});
}

void RegisterBuiltinSegmenters(SegmenterRegistry& registry) {
  std::vector<SegmenterEntry> entries;
  entries.push_back(OracleSegmenterEntry());
  entries.push_back(OraclePerfectSegmenterEntry());
  entries.push_back(ColorSegmenterEntry());
  for (SegmenterEntry& e : entries) {
    const std::string name = e.name;
    const Status s = registry.Add(std::move(e));
    AVP_THROW_UNLESS(s.ok(), name, s.message());
  }
}

SegmenterRegistry BuiltinSegmenters() {
  SegmenterRegistry registry;
  RegisterBuiltinSegmenters(registry);
  return registry;
}

}  // namespace avp::segmentation
