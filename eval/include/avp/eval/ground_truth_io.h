#pragma once

#include <nlohmann/json.hpp>

#include <avp/core/status.h>
#include <avp/eval/ground_truth.h>

namespace avp::eval {

/// The ground truth as JSON (what a recording attaches as `ground_truth.json`, docs/recording.md):
///
///     {"format": "avp-ground-truth", "version": 1, "source": "...", "voxel_size_m": s,
///      "voxels": [[x, y, z, fruit_id], ...],           // ascending (x, y, z)
///      "fruits": [{"instance_id", "name", "center_W": [3], "radii": [3]}, ...],
///      "voxels_per_fruit": [[fruit_id, count], ...],    // ascending id
///      "best_visible_fraction": [[fruit_id, f], ...],   // ascending id
///      "views_tried": n, "views_reachable": n,
///      "views": [{"fruit_id", "radius_m", "azimuth_deg", "elevation_deg",
///                 "X_WC": [12 numbers: the 3x4 [R | p], row-major]}, ...]}
///
/// Doubles are written so that they read back bit-identical (nlohmann's shortest round-trip
/// form), and the rotation is stored as its matrix, so GroundTruthFromJson(GroundTruthToJson(g))
/// equals g exactly. The output does not depend on hash-map order.
/// @pre every number of `truth` is finite (JSON has no NaN / infinity).
nlohmann::json GroundTruthToJson(const GroundTruth& truth);

/// Reads GroundTruthToJson's form back. Checked: the format tag and version, every field's type,
/// voxel keys in int32 range, fruit ids in [0, 65535], finite numbers, voxel_size_m > 0,
/// fractions in [0, 1], views_reachable <= views_tried, no duplicate voxel / fruit entry, X_WC a
/// rotation (orthonormal within 1e-6, det +1). Errors: InvalidArgument naming the field (with its
/// index) and the bad value, e.g. "ground truth: voxels[3][1] must be an integer in int32 range,
/// got 1.5".
Result<GroundTruth> GroundTruthFromJson(const nlohmann::json& j);

}  // namespace avp::eval
