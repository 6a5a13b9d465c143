#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

Status MapOptions::Validate() const {
  if (Status s = grid.Validate(); !s.ok()) return s;
  return semantics.Validate();
}

}  // namespace avp::mapping
