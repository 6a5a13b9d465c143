// A mesh entry's parts into pieces, the future scene objects: parts joined by `merge` rules, fruit
// parts split into connected components (`fruit_instances: components`), fruit fragments under the
// size rule joined to their nearest fruit or dropped; each part's fate recorded for the report.

#include <algorithm>
#include <cstdint>
#include <limits>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/text.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"

namespace avp::sim::internal {

double VolumeCm3(const Box3& box) { return box.Volume() * 1e6; }

namespace {

/// Distance between two boxes (0 when they touch or overlap), metres.
double BoxGap(const Box3& a, const Box3& b) {
  const Eigen::Vector3d d =
      (a.min() - b.max()).cwiseMax(b.min() - a.max()).cwiseMax(Eigen::Vector3d::Zero());
  return d.norm();
}

/// Without a size rule, fruit instances whose bounding box is under this fraction of the largest
/// fruit's are pointed out (a warning), as likely fragments.
constexpr double kTinyFruitFraction = 0.02;

/// Per-entry results of the merge and size rules, for warnings and the report.
struct FragmentCounts {
  size_t name_merged = 0;
  size_t small_merged = 0;
  size_t small_dropped = 0;
  size_t dropped_out_of_reach = 0;
};

/// `into` with each '*' replaced by the corresponding capture of `match`.
std::string SubstituteCaptures(const std::string& into, const std::vector<std::string>& captures) {
  std::string out;
  size_t k = 0;
  for (const char c : into) {
    if (c == '*' && k < captures.size()) {
      out += captures[k++];
    } else {
      out += c;
    }
  }
  return out;
}

/// Warnings for merge rules that match nothing or whose target is missing.
void WarnUnusedMergeRules(const MeshEntry& entry, const std::string& context, size_t num_parts,
                          const std::vector<size_t>& matched,
                          const std::vector<std::vector<std::string>>& unresolved,
                          std::vector<std::string>& warnings) {
  for (size_t m = 0; m < entry.merge.size(); ++m) {
    if (matched[m] == 0) {
      warnings.push_back(fmt::format(
          "{}.merge[{}]: 'match' {} matches no part of {} ({} parts; node and mesh names are "
          "tested)",
          context, m, QuoteText(entry.merge[m].match, 80), QuoteText(entry.file_text, 80),
          num_parts));
    } else if (!unresolved[m].empty()) {
      warnings.push_back(fmt::format(
          "{}.merge[{}]: {} of the {} parts matching {} found no part named by 'into' {} and stay "
          "on their own: {}",
          context, m, unresolved[m].size(), matched[m], QuoteText(entry.merge[m].match, 80),
          QuoteText(entry.merge[m].into, 80), NameList(unresolved[m])));
    }
  }
}

/// Parts joined by `merge` rules (part index -> target part index, -1: none), with the warnings
/// for rules that match nothing or whose target is missing.
std::vector<int> ResolveMergeRules(const MeshEntry& entry, const std::string& context,
                                   const std::vector<ImportedPart>& parts,
                                   std::vector<int>& rule_of_part,
                                   std::vector<std::string>& warnings) {
  std::vector<int> target(parts.size(), -1);
  rule_of_part.assign(parts.size(), -1);
  if (entry.merge.empty()) return target;
  // Which parts are sources (they never become targets themselves), with their captures.
  std::vector<std::vector<std::string>> captures(parts.size());
  for (size_t i = 0; i < parts.size(); ++i) {
    for (size_t m = 0; m < entry.merge.size(); ++m) {
      if (GlobCapture(entry.merge[m].match, parts[i].node_name, &captures[i]) ||
          GlobCapture(entry.merge[m].match, parts[i].mesh_name, &captures[i])) {
        rule_of_part[i] = static_cast<int>(m);
        break;
      }
    }
  }
  // Targets by exact node or mesh name (the first part of each name), for `into` without
  // wildcards once substituted: no scan over every part per fragment.
  std::unordered_map<std::string, size_t> by_name;
  for (size_t j = 0; j < parts.size(); ++j) {
    if (rule_of_part[j] >= 0) continue;
    by_name.emplace(parts[j].node_name, j);
    by_name.emplace(parts[j].mesh_name, j);
  }
  std::vector<size_t> matched(entry.merge.size(), 0);
  std::vector<std::vector<std::string>> unresolved(entry.merge.size());
  for (size_t i = 0; i < parts.size(); ++i) {
    if (rule_of_part[i] < 0) continue;
    const MergeRule& rule = entry.merge[static_cast<size_t>(rule_of_part[i])];
    ++matched[static_cast<size_t>(rule_of_part[i])];
    const std::string into = SubstituteCaptures(rule.into, captures[i]);
    if (into.find_first_of("*?") == std::string::npos) {
      if (const auto it = by_name.find(into); it != by_name.end()) {
        target[i] = static_cast<int>(it->second);
      }
    } else {
      for (size_t j = 0; j < parts.size(); ++j) {
        if (rule_of_part[j] >= 0) continue;
        if (GlobMatch(into, parts[j].node_name) || GlobMatch(into, parts[j].mesh_name)) {
          target[i] = static_cast<int>(j);
          break;
        }
      }
    }
    if (target[i] < 0) unresolved[static_cast<size_t>(rule_of_part[i])].push_back(parts[i].name);
  }
  WarnUnusedMergeRules(entry, context, parts.size(), matched, unresolved, warnings);
  return target;
}

/// The pieces of the parts not merged by name: a part, or each connected component of a fruit
/// part; `pieces_of[p]`: the pieces of part p.
std::vector<Piece> SplitIntoPieces(const MeshEntry& entry, std::vector<ImportedPart>& parts,
                                   const std::vector<int>& merge_target,
                                   std::vector<std::vector<size_t>>& pieces_of) {
  std::vector<Piece> pieces;
  pieces_of.assign(parts.size(), {});
  for (size_t p = 0; p < parts.size(); ++p) {
    if (merge_target[p] >= 0) continue;
    std::vector<TriangleMesh> meshes_of_part;
    if (parts[p].semantic_class == SemanticClass::kFruit &&
        entry.fruit_instances == FruitInstances::kComponents) {
      meshes_of_part = ConnectedComponents(parts[p].mesh);
    } else {
      meshes_of_part.push_back(std::move(parts[p].mesh));
    }
    for (size_t k = 0; k < meshes_of_part.size(); ++k) {
      Piece piece;
      piece.mesh = std::move(meshes_of_part[k]);
      piece.part = p;
      piece.name =
          meshes_of_part.size() > 1 ? fmt::format("{}#{}", parts[p].name, k) : parts[p].name;
      pieces_of[p].push_back(pieces.size());
      pieces.push_back(std::move(piece));
    }
  }
  return pieces;
}

/// A part merged by name joins the nearest piece of its target part (the target may have been
/// split into components).
void MergeByName(const MeshEntry& entry, const std::vector<ImportedPart>& parts,
                 const std::vector<int>& merge_target, const std::vector<int>& merge_rule_of,
                 const std::vector<std::vector<size_t>>& pieces_of, std::vector<Piece>& pieces,
                 size_t first_report, SceneFileReport& rep, FragmentCounts& counts) {
  for (size_t p = 0; p < parts.size(); ++p) {
    if (merge_target[p] < 0) continue;
    const std::vector<size_t>& candidates = pieces_of[static_cast<size_t>(merge_target[p])];
    const Box3 box = parts[p].mesh.Bounds();
    size_t best = candidates.front();
    double best_gap = std::numeric_limits<double>::infinity();
    for (const size_t c : candidates) {
      const double gap = BoxGap(box, pieces[c].mesh.Bounds());
      if (gap < best_gap) {
        best_gap = gap;
        best = c;
      }
    }
    const MergeRule& rule = entry.merge[static_cast<size_t>(merge_rule_of[p])];
    SceneFragmentReport fragment;
    fragment.name = parts[p].name;
    fragment.into = pieces[best].name;
    fragment.reason = fmt::format("merge[{}] {}", merge_rule_of[p], QuoteText(rule.match, 80));
    fragment.vertices = parts[p].mesh.vertices.size();
    fragment.volume_cm3 = VolumeCm3(box);
    fragment.gap_mm = best_gap * 1000.0;
    rep.parts[first_report + p].fate.push_back(
        fmt::format("merged into {} (merge[{}])", pieces[best].name, merge_rule_of[p]));
    rep.parts[first_report + p].semantic_class =
        parts[static_cast<size_t>(merge_target[p])].semantic_class;
    // Each part keeps its own colour (per-triangle colours where they differ).
    pieces[best].mesh.Append(parts[p].mesh, RigidTransform::Identity(),
                             parts[pieces[best].part].albedo, parts[p].albedo);
    pieces[best].merged.push_back(parts[p].name);
    rep.fragments.push_back(std::move(fragment));
    ++counts.name_merged;
  }
}

/// Small fruit piece `k` joins its nearest anchor within reach, or is dropped.
SceneFragmentReport MergeOrDropSmallFruit(const MeshEntry& entry,
                                          const std::vector<ImportedPart>& parts, size_t k,
                                          const std::vector<size_t>& anchors,
                                          const std::vector<Box3>& bounds,
                                          std::vector<Piece>& pieces, FragmentCounts& counts) {
  SceneFragmentReport fragment;
  fragment.name = pieces[k].name;
  fragment.vertices = pieces[k].mesh.vertices.size();
  fragment.volume_cm3 = VolumeCm3(bounds[k]);
  size_t best = 0;
  double best_gap = std::numeric_limits<double>::infinity();
  for (const size_t a : anchors) {
    const double gap = BoxGap(bounds[k], bounds[a]);
    if (gap < best_gap) {
      best_gap = gap;
      best = a;
    }
  }
  pieces[k].removed = true;
  if (entry.fruit_small_parts == SmallParts::kMerge &&
      best_gap * 1000.0 <= entry.fruit_merge_reach_mm) {
    fragment.into = pieces[best].name;
    fragment.reason = "small";
    fragment.gap_mm = best_gap * 1000.0;
    pieces[k].fate =
        fmt::format("merged into {} (small, {:.1f} mm away)", pieces[best].name, fragment.gap_mm);
    pieces[best].mesh.Append(pieces[k].mesh, RigidTransform::Identity(),
                             parts[pieces[best].part].albedo, parts[pieces[k].part].albedo);
    pieces[best].merged.push_back(pieces[k].name);
    for (const std::string& inner : pieces[k].merged) pieces[best].merged.push_back(inner);
    ++counts.small_merged;
  } else if (entry.fruit_small_parts == SmallParts::kMerge) {
    fragment.reason = "small, no fruit within reach";
    pieces[k].fate =
        fmt::format("dropped (small, no fruit within {} mm)", entry.fruit_merge_reach_mm);
    ++counts.small_dropped;
    ++counts.dropped_out_of_reach;
  } else {
    fragment.reason = "small";
    pieces[k].fate = "dropped (small)";
    ++counts.small_dropped;
  }
  return fragment;
}

/// Fruit pieces under the minimum size join their nearest fruit within reach, or are dropped;
/// one warning sums it up.
void ApplyFruitSizeRule(const MeshEntry& entry, const std::string& context,
                        const std::vector<ImportedPart>& parts,
                        const std::vector<size_t>& fruit_pieces, std::vector<Piece>& pieces,
                        SceneFileReport& rep, FragmentCounts& counts) {
  std::vector<size_t> small, anchors;
  std::vector<Box3> bounds(pieces.size());
  for (const size_t k : fruit_pieces) {
    bounds[k] = pieces[k].mesh.Bounds();
    const bool is_small =
        VolumeCm3(bounds[k]) < entry.fruit_min_volume_cm3 ||
        static_cast<int64_t>(pieces[k].mesh.vertices.size()) < entry.fruit_min_vertices;
    (is_small ? small : anchors).push_back(k);
  }
  for (const size_t k : small) {
    rep.fragments.push_back(
        MergeOrDropSmallFruit(entry, parts, k, anchors, bounds, pieces, counts));
  }
  if (counts.small_merged + counts.small_dropped == 0) return;
  std::vector<std::string> minimum;
  if (entry.fruit_min_volume_cm3 > 0.0) {
    minimum.push_back(fmt::format("a bounding box under {} cm3", entry.fruit_min_volume_cm3));
  }
  if (entry.fruit_min_vertices > 0) {
    minimum.push_back(fmt::format("fewer than {} vertices", entry.fruit_min_vertices));
  }
  rep.warnings.push_back(fmt::format(
      "{} ({}): {} fruit fragments under the minimum size ({}): {} joined their nearest "
      "fruit, {} dropped{}; {} fruits remain",
      context, QuoteText(entry.file_text, 80), small.size(), fmt::join(minimum, " or "),
      counts.small_merged, counts.small_dropped,
      counts.dropped_out_of_reach > 0
          ? fmt::format(" ({} with no fruit within {} mm)", counts.dropped_out_of_reach,
                        entry.fruit_merge_reach_mm)
          : std::string(),
      anchors.size()));
}

/// No size rule: point at fragments far smaller than the largest fruit.
void WarnTinyFruits(const MeshEntry& entry, const std::string& context,
                    const std::vector<size_t>& fruit_pieces, const std::vector<Piece>& pieces,
                    std::vector<std::string>& warnings) {
  std::vector<double> volumes;
  for (const size_t k : fruit_pieces) volumes.push_back(VolumeCm3(pieces[k].mesh.Bounds()));
  const double largest = *std::max_element(volumes.begin(), volumes.end());
  std::vector<std::string> tiny;
  for (size_t f = 0; f < fruit_pieces.size(); ++f) {
    if (volumes[f] < kTinyFruitFraction * largest) tiny.push_back(pieces[fruit_pieces[f]].name);
  }
  if (!tiny.empty()) {
    warnings.push_back(fmt::format(
        "{} ({}): {} of its {} fruit instances have a bounding box under 2% of the largest "
        "fruit's ({:.3g} cm3): {}; if they are fragments of fruit, set fruit_min_volume_cm3 "
        "(they then join their nearest fruit) or a 'merge' rule",
        context, QuoteText(entry.file_text, 80), tiny.size(), fruit_pieces.size(), largest,
        NameList(tiny)));
  }
}

}  // namespace

std::vector<Piece> FormPieces(const MeshEntry& entry, const std::string& context,
                              std::vector<ImportedPart>& parts, size_t first_report,
                              SceneFileReport& rep) {
  std::vector<int> merge_rule_of;
  const std::vector<int> merge_target =
      ResolveMergeRules(entry, context, parts, merge_rule_of, rep.warnings);
  FragmentCounts counts;
  std::vector<std::vector<size_t>> pieces_of;
  std::vector<Piece> pieces = SplitIntoPieces(entry, parts, merge_target, pieces_of);
  MergeByName(entry, parts, merge_target, merge_rule_of, pieces_of, pieces, first_report, rep,
              counts);
  std::vector<size_t> fruit_pieces;
  for (size_t k = 0; k < pieces.size(); ++k) {
    if (parts[pieces[k].part].semantic_class == SemanticClass::kFruit) fruit_pieces.push_back(k);
  }
  if (entry.fruit_min_volume_cm3 > 0.0 || entry.fruit_min_vertices > 0) {
    ApplyFruitSizeRule(entry, context, parts, fruit_pieces, pieces, rep, counts);
  } else if (fruit_pieces.size() >= 2) {
    WarnTinyFruits(entry, context, fruit_pieces, pieces, rep.warnings);
  }
  // Part reports: what became of each piece.
  for (size_t p = 0; p < parts.size(); ++p) {
    for (const size_t k : pieces_of[p]) {
      rep.parts[first_report + p].fate.push_back(
          pieces_of[p].size() > 1 ? fmt::format("{}: {}", pieces[k].name, pieces[k].fate)
                                  : pieces[k].fate);
    }
  }
  return pieces;
}

}  // namespace avp::sim::internal
