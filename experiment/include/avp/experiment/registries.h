#pragma once

#include <avp/planning/planner_registry.h>
#include <avp/segmentation/segmenter_registry.h>
#include <avp/sim/scenario.h>

namespace avp::experiment {

/// Everything a user picks by name: planners, segmenters, scenarios. A program builds one at
/// start-up (BuiltinRegistries, then whatever it adds: the network backends, the remote client)
/// and hands it to the commands; read-only afterwards.
struct Registries {
  planning::PlannerRegistry planners;
  segmentation::SegmenterRegistry segmenters;
  sim::ScenarioRegistry scenarios;
};

/// The built-ins, registered from this one place: planning's planners, then eval's diagnostic
/// oracle planners (which need the ground truth), segmentation's segmenters and sim's
/// scenarios.
Registries BuiltinRegistries();

}  // namespace avp::experiment
