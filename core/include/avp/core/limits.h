#pragma once

// Budgets for everything that input controls (docs/limits.md lists every limit, its default and
// where to change it). A limit is checked before the work or the allocation it guards, and an
// input past it gets ResourceExhausted naming the limit, the amount asked for and how to raise it.
//
// Limits that guard a library's reading (image pixels, mesh vertices, file sizes) are process-wide
// named values: declared once next to the code they guard, listed by `avp limits`, raised with
// `avp --limit NAME=VALUE ...` or the environment (AVP_LIMITS="NAME=VALUE,NAME=VALUE"):
//
//   const Limit& MaxImagePixels() {
//     static const Limit limit("max_image_pixels", 64ull << 20, "pixels",
//                              "pixels of one decoded image (colour, depth, mask)");
//     return limit;
//   }
//   AVP_RETURN_IF_ERROR(MaxImagePixels().Check("image of 20000 x 20000 pixels", w * h));
//
// Limits that belong to one object's configuration (a server's queue depth, a planner's candidate
// count) are fields of its options struct instead, with a range in its option table.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp {

/// ResourceExhausted: "<what> (<amount>) exceeds the limit <limit_name> = <limit>" and
/// "; <how_to_raise>" when given. For example ExceedsLimit("image of 20000 x 20000 pixels",
/// 400000000, "max_image_pixels", 67108864, "raise it with --max-image-pixels").
Status ExceedsLimit(std::string_view what, uint64_t amount, std::string_view limit_name,
                    uint64_t limit, std::string_view how_to_raise = "");

/// OK when amount <= limit, else ExceedsLimit(...).
inline Status CheckLimit(std::string_view what, uint64_t amount, std::string_view limit_name,
                         uint64_t limit, std::string_view how_to_raise = "") {
  if (amount <= limit) return Status::Ok();
  return ExceedsLimit(what, amount, limit_name, limit, how_to_raise);
}

/// One process-wide limit as `avp limits` lists it.
struct LimitInfo {
  std::string name;  ///< "max_image_pixels"
  uint64_t value = 0;
  uint64_t default_value = 0;
  std::string unit;  ///< "pixels", "bytes", "vertices"
  std::string doc;   ///< one line
};

/// A named process-wide limit. Construct it once (a function-local static, as above): it registers
/// itself under its name, which must be unique ([a-z0-9_]+). Thread-safe.
class Limit {
 public:
  Limit(std::string_view name, uint64_t default_value, std::string_view unit, std::string_view doc);
  Limit(const Limit&) = delete;
  Limit& operator=(const Limit&) = delete;

  const std::string& name() const;
  uint64_t value() const;
  /// OK when amount <= value(), else ResourceExhausted naming the limit and "raise it with
  /// --limit <name>=N (docs/limits.md)".
  Status Check(std::string_view what, uint64_t amount) const;

  struct Entry;  ///< the registry's record (internal)

 private:
  Entry* entry_;
};

/// Sets a registered limit. NotFound naming the known limits for an unknown name, InvalidArgument
/// for 0 (a limit turns nothing off).
Status SetLimit(std::string_view name, uint64_t value);
/// "NAME=VALUE[,NAME=VALUE...]", VALUE a whole number >= 1 (e.g. "max_image_pixels=400000000").
/// Each pair applied in order; the first bad one is the error, naming it.
Status SetLimits(std::string_view assignments);
/// Every limit registered so far, by name.
std::vector<LimitInfo> RegisteredLimits();

/// Sets a limit for a scope (tests): restores the previous value on destruction.
class ScopedLimit {
 public:
  ScopedLimit(const Limit& limit, uint64_t value);
  ~ScopedLimit();
  ScopedLimit(const ScopedLimit&) = delete;
  ScopedLimit& operator=(const ScopedLimit&) = delete;

 private:
  std::string name_;
  uint64_t previous_;
};

}  // namespace avp
