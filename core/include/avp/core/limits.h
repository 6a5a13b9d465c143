#pragma once

// Budgets for everything that input controls (docs/limits.md lists every limit, its default and
// where to change it). A limit is checked before the work or the allocation it guards, and an
// input past it gets ResourceExhausted naming the limit, the amount asked for and how to raise it.

#include <cstdint>
#include <string_view>

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

}  // namespace avp
