#include <avp/eval/oracle_planner.h>
#include <avp/experiment/registries.h>

namespace avp::experiment {

Registries BuiltinRegistries() {
  Registries r;
  planning::RegisterBuiltinPlanners(r.planners);
  eval::RegisterOraclePlanners(r.planners);
  segmentation::RegisterBuiltinSegmenters(r.segmenters);
  sim::RegisterBuiltinScenarios(r.scenarios);
  return r;
}

}  // namespace avp::experiment
