#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

const OptionTable<MapOptions>& MapOptionTable() {
  static const auto* table = [] {
    auto* t = new OptionTable<MapOptions>("map option");
    t->Nested("grid", &MapOptions::grid, GridOptionTable());
    t->Nested("semantics", &MapOptions::semantics, SemanticOptionTable());
    return t;
  }();
  return *table;
}

Status MapOptions::Validate() const { return MapOptionTable().Validate(*this); }

}  // namespace avp::mapping
