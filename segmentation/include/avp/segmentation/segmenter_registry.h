#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/options.h>
#include <avp/core/registry.h>
#include <avp/core/status.h>
#include <avp/segmentation/segmenter.h>

namespace avp::segmentation {

/// What a segmenter's factory gets besides its spec and options.
struct SegmenterContext {
  /// Seeds the segmenter's randomness (the run's segmenter stream); deterministic segmenters
  /// ignore it.
  uint64_t seed = 0;
};

/// One segmenter a user can pick by name (`--segmenter NAME`, `avp segment --backend NAME`,
/// `avp serve segmentation --backend NAME`). A name ending in "://" is a scheme: it matches every
/// spec that starts with it ("remote://host:port/model", "ywes:///opt/models"), and the factory
/// reads the rest of the spec.
struct SegmenterEntry {
  std::string name;
  /// One line for `--segmenter help`.
  std::string description;
  /// The options type with its defaults (no fields: none).
  AnyOptions options;
  /// Builds the segmenter for `spec` (the name, or the whole scheme spec) with options of
  /// `options`' type (already validated).
  std::function<Result<std::unique_ptr<Segmenter>>(std::string_view spec, const AnyOptions&,
                                                   const SegmenterContext&)>
      make;
  /// Optional, cheap: checks `spec` with options of `options`' type (validated) without building
  /// the segmenter (a model directory that exists and holds what the backend needs; a remote
  /// spec that parses), so that a run refuses a bad one before it writes anything. Empty: nothing
  /// beyond the options to check.
  std::function<Status(std::string_view spec, const AnyOptions&)> check;
  bool is_scheme() const;

  /// The name, or (a scheme) a spec that starts with it.
  bool Matches(std::string_view spec) const;
  /// Schemes as "remote://...".
  std::string DisplayName() const { return is_scheme() ? name + "..." : name; }
  bool HasFactory() const { return static_cast<bool>(make); }
};

/// An entry for a segmenter with options of type Options.
template <typename Options>
SegmenterEntry MakeSegmenterEntry(std::string name, std::string description,
                                  const OptionTable<Options>& table, Options defaults,
                                  std::function<Result<std::unique_ptr<Segmenter>>(
                                      std::string_view, const Options&, const SegmenterContext&)>
                                      make) {
  SegmenterEntry e;
  e.name = std::move(name);
  e.description = std::move(description);
  e.options = AnyOptions(table, std::move(defaults));
  e.make = [make = std::move(make)](std::string_view spec, const AnyOptions& o,
                                    const SegmenterContext& c) {
    return make(spec, o.As<Options>(), c);
  };
  return e;
}

/// The segmenters a program knows, in registration order (NamedRegistry: Add, Find, Get, Names,
/// entries; Find matches a scheme by prefix). Built once at start-up
/// (RegisterBuiltinSegmenters, then the network backends and the remote client register theirs),
/// read-only afterwards.
class SegmenterRegistry : public NamedRegistry<SegmenterEntry> {
 public:
  SegmenterRegistry() : NamedRegistry("segmenter") {}
  /// Builds `spec` with `options` (of its entry's type; validated here).
  Result<std::unique_ptr<Segmenter>> Make(std::string_view spec, const AnyOptions& options,
                                          const SegmenterContext& context) const;
  /// Builds `spec` with its entry's default options.
  Result<std::unique_ptr<Segmenter>> Make(std::string_view spec, uint64_t seed) const;
  /// Checks `spec` with `options` (of its entry's type) as far as it can without building it
  /// (SegmenterEntry::check): what Make would refuse at once, found before anything runs.
  Status Check(std::string_view spec, const AnyOptions& options) const;
};

/// Registers this module's segmenters, in this order: "oracle" (OracleSegmenter with
/// OracleOptions{}), "oracle-perfect" (OracleOptions::Perfect()), "color" (ColorSegmenter).
/// @throws avp::Error if a name is already taken.
void RegisterBuiltinSegmenters(SegmenterRegistry& registry);

/// A registry with RegisterBuiltinSegmenters only (tests, tools).
SegmenterRegistry BuiltinSegmenters();

}  // namespace avp::segmentation
