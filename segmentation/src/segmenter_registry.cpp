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

bool SegmenterEntry::Matches(std::string_view spec) const {
  return name == spec || (is_scheme() && spec.substr(0, name.size()) == name);
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

Status SegmenterRegistry::Check(std::string_view spec, const AnyOptions& options) const {
  AVP_ASSIGN_OR_RETURN(const SegmenterEntry* entry, Get(spec));
  AVP_RETURN_IF_ERROR(options.Validate());
  return entry->check ? entry->check(spec, options) : Status::Ok();
}

void RegisterBuiltinSegmenters(SegmenterRegistry& registry) {
  std::vector<SegmenterEntry> entries;
  entries.push_back(OracleSegmenterEntry());
  entries.push_back(OraclePerfectSegmenterEntry());
  entries.push_back(ColorSegmenterEntry());
  AddAll(registry, std::move(entries));
}

SegmenterRegistry BuiltinSegmenters() {
  SegmenterRegistry registry;
  RegisterBuiltinSegmenters(registry);
  return registry;
}

}  // namespace avp::segmentation
