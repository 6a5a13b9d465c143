#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/mapping/map_tools.h>
#include <avp/mapping/ply_export.h>
#include <avp/mapping/semantic_map.h>

namespace avp::mapping {

namespace fs = std::filesystem;

namespace {

std::string FormatPoint(const Eigen::Vector3d& p, int decimals = 3) {
  return fmt::format("({:.{}f}, {:.{}f}, {:.{}f})", p.x(), decimals, p.y(), decimals, p.z(),
                     decimals);
}

}  // namespace

std::string HumanBytes(uint64_t bytes) {
  if (bytes < 1024) return fmt::format("{} B", bytes);
  if (bytes < 1024 * 1024) return fmt::format("{:.1f} KiB", static_cast<double>(bytes) / 1024.0);
  if (bytes < uint64_t{1} << 30) {
    return fmt::format("{:.1f} MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  }
  return fmt::format("{:.2f} GiB", static_cast<double>(bytes) / (1024.0 * 1024.0 * 1024.0));
}

// ---- info
// ----------------------------------------------------------------------------------------

Result<MapInfo> ReadMapInfo(const fs::path& path) {
  MapInfo info;
  info.path = path;
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(path, "map file").status());
  AVP_ASSIGN_OR_RETURN(const LoadedMap loaded, LoadAnyMap(path));
  info.source = loaded.source;
  info.file = loaded.source.avpmap;
  const SemanticMap& map = loaded.map;
  const OccupancyGrid& grid = map.grid();
  info.options = map.options();
  info.blocks = grid.num_blocks();
  info.semantic_blocks = grid.num_semantic_blocks();
  info.known_voxels = grid.CountKnownVoxels();
  info.occupied_voxels = grid.CountOccupiedVoxels();
  info.free_voxels = info.known_voxels - info.occupied_voxels;
  info.labelled_voxels = grid.CountSemanticVoxels();
  grid.ForEachSemanticVoxel([&](const VoxelKey& k, const SemanticCell& cell) {
    if (cell.semantic_class >= kNumSemanticClasses) return;
    ++info.labelled_by_class[cell.semantic_class];
    if (grid.State(k) == VoxelState::kOccupied) ++info.occupied_by_class[cell.semantic_class];
  });
  info.instances = map.Instances();
  info.known_bounds = grid.KnownBounds();
  info.memory_bytes = grid.MemoryBytes();
  return info;
}

std::string FormatMapInfo(const MapInfo& info) {
  const GridOptions& g = info.options.grid;
  const SemanticOptions& s = info.options.semantics;
  std::string out;
  const auto line = [&](std::string_view key, const std::string& value) {
    out += fmt::format("{:<13}{}\n", key, value);
  };
  const MapSource& src = info.source;
  const bool octomap = src.format != MapFileFormat::kAvpMap;
  if (!octomap) {
    line("map file",
         fmt::format("{} ({}, format version {}, CRC-32 0x{:08x})", info.path.string(),
                     HumanBytes(info.file.file_bytes), info.file.version, info.file.crc32));
  } else {
    line("map file", fmt::format("{} ({}, OctoMap {} {}, {} tree nodes)", info.path.string(),
                                 HumanBytes(src.file_bytes), EscapeText(src.tree_type, 64),
                                 MapFileExtension(src.format), src.tree_nodes));
    line("leaves", fmt::format("{} occupied, {} free ({} coarser than one voxel, expanded)",
                               src.occupied_leaves, src.free_leaves, src.coarse_leaves));
    if (src.tree_type == "ColorOcTree") {
      line("colours", fmt::format("{} occupied voxels in a class colour (read as that class), {} "
                                  "in avp's unlabelled grey, {} in other colours (unlabelled)",
                                  src.labelled_by_colour, src.unlabelled_grey, src.foreign_colour));
    }
    for (const std::string& lost : src.lost) line("not kept", lost);
  }
  if (!src.extension_note.empty()) line("note", src.extension_note);
  // The note is the file's text: escaped, so that a crafted map cannot reach the terminal.
  if (!info.file.note.empty()) line("made by", EscapeText(info.file.note, 1000));
  line("voxel size", fmt::format("{:g} mm", g.voxel_size_m * 1000.0));
  line("lattice", "voxel k covers [k s, (k + 1) s) on each axis (a voxel corner at the origin)");
  line("ROI", g.roi ? fmt::format("{} - {} m", FormatPoint(g.roi->min()), FormatPoint(g.roi->max()))
                    : std::string("none"));
  if (!octomap) {
    line("sensor model",
         fmt::format("hit {:g}, miss {:g}, clamp [{:g}, {:g}], occupied at p >= {:g}", g.sensor.hit,
                     g.sensor.miss, g.sensor.clamp_min, g.sensor.clamp_max,
                     g.sensor.occupied_threshold));
    if (s.policy == FusionPolicy::kReferenceMax) {
      line("fusion", fmt::format("{} (penalty {:g})", ToString(s.policy), s.reference_penalty));
    } else {
      line("fusion", fmt::format("{} (class log-odds [{:g}, {:g}], miss {:g}, label at p >= {:g})",
                                 ToString(s.policy), s.class_log_odds_min, s.class_log_odds_max,
                                 s.miss_log_odds, s.label_threshold));
    }
  }
  line("blocks",
       fmt::format("{} of 8^3 voxels ({} with semantics)", info.blocks, info.semantic_blocks));
  line("voxels", fmt::format("{} known: {} free, {} occupied; {} labelled", info.known_voxels,
                             info.free_voxels, info.occupied_voxels, info.labelled_voxels));
  std::string classes;
  for (SemanticClass c : AllSemanticClasses()) {
    const auto i = static_cast<size_t>(c);
    if (info.labelled_by_class[i] == 0) continue;
    if (!classes.empty()) classes += ", ";
    classes += fmt::format("{} {} ({} occupied)", ToString(c), info.labelled_by_class[i],
                           info.occupied_by_class[i]);
  }
  line("labels", classes.empty() ? std::string("none") : classes);
  line("bounds", info.known_bounds.IsEmpty()
                     ? std::string("empty")
                     : fmt::format("{} - {} m (known voxels)", FormatPoint(info.known_bounds.min()),
                                   FormatPoint(info.known_bounds.max())));
  line("memory", HumanBytes(info.memory_bytes) + " (blocks, semantic payload, hash table)");
  // Instances are not fruit: say what they are, so that 31 instances of 15 fruit is no puzzle.
  line("instances", info.instances.empty()
                        ? std::string("0")
                        : fmt::format("{} (segments of the fused masks: a fruit seen in pieces, or "
                                      "a false detection, is an instance of its own; avp map "
                                      "compare --gt counts the fruit found)",
                                      info.instances.size()));
  if (!info.instances.empty()) {
    out += fmt::format("  {:>5}  {:<8} {:>7}  {:<26} {}\n", "id", "class", "voxels", "centroid (m)",
                       "mean confidence");
    for (const InstanceInfo& inst : info.instances) {
      out += fmt::format("  {:>5}  {:<8} {:>7}  {:<26} {:.3f}\n", inst.id,
                         ToString(inst.semantic_class), inst.voxels, FormatPoint(inst.centroid_W),
                         inst.mean_confidence);
    }
  }
  return out;
}

// ---- export
// --------------------------------------------------------------------------------------

std::optional<MapExportFormat> MapExportFormatFromString(std::string_view name) {
  if (name == "bt") return MapExportFormat::kBt;
  if (name == "ot") return MapExportFormat::kOt;
  if (name == "ply") return MapExportFormat::kPly;
  if (name == "avpmap") return MapExportFormat::kAvpMap;
  return std::nullopt;
}

namespace {

/// The export format: --format, else the extension of --out. Errors: an unknown name, naming it
/// and where it came from; --voxels other than labelled with a format other than PLY.
Result<MapExportFormat> ResolveExportFormat(const MapExportOptions& options) {
  std::string format = options.format;
  if (format.empty()) {
    format = options.out.extension().string();
    if (!format.empty() && format[0] == '.') format.erase(0, 1);
  }
  const std::optional<MapExportFormat> f = MapExportFormatFromString(format);
  if (!f) {
    return InvalidArgumentError(fmt::format(
        "unknown export format {} (from {}): use avpmap, bt, ot or ply", QuoteText(format),
        options.format.empty() ? "the extension of --out" : "--format"));
  }
  if (*f != MapExportFormat::kPly && options.ply_voxels != PlyVoxels::kLabelled) {
    return InvalidArgumentError(fmt::format(
        "--voxels {} applies to PLY only, not to format {} (from {}): write a .ply file or "
        "leave --voxels out",
        ToString(options.ply_voxels), QuoteText(format),
        options.format.empty() ? "the extension of --out" : "--format"));
  }
  return *f;
}

/// The .avpmap branch of ExportMapFile: SaveMap with a note saying where the map came from.
Status ExportAvpMap(const SemanticMap& map, const MapSource& source,
                    const MapExportOptions& options, MapExportSummary& summary) {
  MapSaveOptions save;
  save.note = fmt::format("avp map export of {} ({}{})", source.path.filename().string(),
                          ToString(source.format),
                          source.tree_type.empty() ? std::string() : ", " + source.tree_type);
  if (source.format == MapFileFormat::kAvpMap && !source.avpmap.note.empty()) {
    save.note += "; made by: " + source.avpmap.note;
  }
  if (save.note.size() > kMaxMapNoteBytes) save.note.resize(kMaxMapNoteBytes);
  AVP_RETURN_IF_ERROR(SaveMap(map, options.out, save));
  summary.occupied_voxels = map.grid().CountOccupiedVoxels();
  summary.free_voxels = map.grid().CountKnownVoxels() - summary.occupied_voxels;
  summary.labelled_voxels = map.grid().CountSemanticVoxels();
  std::error_code ec;
  summary.file_bytes = fs::file_size(options.out, ec);
  return Status::Ok();
}

/// The PLY branch of ExportMapFile: ExportSemanticPly with --ascii and --voxels.
Status ExportPly(const SemanticMap& map, const MapExportOptions& options,
                 MapExportSummary& summary) {
  PlyExportOptions ply;
  ply.binary = !options.ply_ascii;
  ply.voxels = options.ply_voxels;
  AVP_ASSIGN_OR_RETURN(const PlyExportStats stats, ExportSemanticPly(map.grid(), options.out, ply));
  summary.ply_voxels = options.ply_voxels;
  summary.labelled_voxels = stats.labelled;
  summary.unlabelled_voxels = stats.unlabelled;
  summary.not_occupied_voxels = stats.not_occupied;
  summary.occupied_voxels = stats.vertices - stats.not_occupied;
  summary.file_bytes = stats.file_bytes;
  return Status::Ok();
}

}  // namespace

Result<MapExportSummary> ExportMapFile(const MapExportOptions& options) {
  if (options.out.empty()) return InvalidArgumentError("give the output file with --out");
  // A bad format is refused before the map is read.
  AVP_RETURN_IF_ERROR(ResolveExportFormat(options).status());
  // Outputs never overwrite inputs: `map export X --out X` would replace the map it reads.
  AVP_RETURN_IF_ERROR(
      io::CheckOutputIsNotInput(options.out, "export file (--out)", options.map, "map file"));
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.map, "map file").status());
  AVP_ASSIGN_OR_RETURN(const LoadedMap loaded, LoadAnyMap(options.map));
  return ExportMap(loaded.map, loaded.source, options);
}

Result<MapExportSummary> ExportMap(const SemanticMap& map, const MapSource& source,
                                   const MapExportOptions& options) {
  if (options.out.empty()) return InvalidArgumentError("give the output file with --out");
  AVP_ASSIGN_OR_RETURN(const MapExportFormat f, ResolveExportFormat(options));
  if (!source.path.empty()) {
    AVP_RETURN_IF_ERROR(
        io::CheckOutputIsNotInput(options.out, "export file (--out)", source.path, "map file"));
  }
  MapExportSummary summary;
  summary.format = f;
  summary.out = options.out;
  summary.source = source;
  if (f == MapExportFormat::kAvpMap) {
    AVP_RETURN_IF_ERROR(ExportAvpMap(map, source, options, summary));
    return summary;
  }
  if (f == MapExportFormat::kPly) {
    AVP_RETURN_IF_ERROR(ExportPly(map, options, summary));
    return summary;
  }
  AVP_ASSIGN_OR_RETURN(const OctomapExportStats stats,
                       f == MapExportFormat::kBt ? ExportOctomapBinary(map.grid(), options.out)
                                                 : ExportOctomapColor(map, options.out));
  summary.occupied_voxels = stats.occupied_voxels;
  summary.free_voxels = stats.free_voxels;
  summary.labelled_voxels = stats.labelled_voxels;
  summary.file_bytes = stats.file_bytes;
  return summary;
}

// ---- compare
// -------------------------------------------------------------------------------------

Result<MapCompareSummary> CompareMapFiles(const MapCompareOptions& options) {
  GroundTruthCompareOptions compare;
  compare.tolerance_voxels = options.tolerance_voxels;
  compare.semantic_class = options.semantic_class;
  AVP_RETURN_IF_ERROR(compare.Validate());
  if (!options.json_out.empty()) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.json_out, "result file (--json)",
                                                  options.map, "map file"));
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.json_out, "result file (--json)",
                                                  options.gt, "ground truth file"));
  }
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.map, "map file").status());
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.gt, "ground truth file").status());
  AVP_ASSIGN_OR_RETURN(const LoadedMap loaded, LoadAnyMap(options.map));
  AVP_ASSIGN_OR_RETURN(const LoadedMap gt_map, LoadAnyMap(options.gt));
  AVP_ASSIGN_OR_RETURN(MapCompareSummary summary,
                       CompareMaps(loaded.map, loaded.source, gt_map.map, gt_map.source, options));
  if (!options.json_out.empty()) {
    AVP_RETURN_IF_ERROR(io::WriteJsonFile(options.json_out, ToJson(summary)));
  }
  return summary;
}

Result<MapCompareSummary> CompareMaps(const SemanticMap& map, const MapSource& source,
                                      const SemanticMap& gt_map, const MapSource& gt_source,
                                      const MapCompareOptions& options) {
  GroundTruthCompareOptions compare;
  compare.tolerance_voxels = options.tolerance_voxels;
  compare.semantic_class = options.semantic_class;
  AVP_RETURN_IF_ERROR(compare.Validate());
  MapCompareSummary summary;
  summary.map_source = source;
  const VoxelSet gt =
      GroundTruthVoxels(gt_map, gt_source, options.semantic_class, &summary.gt_used_labels);
  summary.gt_source = gt_source;
  summary.map = options.map;
  summary.gt = options.gt;
  summary.semantic_class = options.semantic_class;
  summary.gt_occupied_leaves = gt.occupied_leaves;
  summary.gt_coarse_leaves = gt.coarse_leaves;
  std::vector<int> tolerances = {0};
  if (options.tolerance_voxels > 0) tolerances.push_back(options.tolerance_voxels);
  for (int t : tolerances) {
    compare.tolerance_voxels = t;
    AVP_ASSIGN_OR_RETURN(GroundTruthComparison r, CompareToGroundTruth(map.grid(), gt, compare));
    summary.results.push_back(r);
  }
  // Lattice check: the best exact F1 over the 26 one-voxel shifts of the prediction.
  {
    const OccupancyGrid& grid = map.grid();
    std::vector<VoxelKey> gt_keys;
    gt_keys.reserve(gt.keys.size());
    for (const VoxelKey& k : gt.keys) {
      gt_keys.push_back(summary.results.front().resampled ? grid.KeyOf(k.Center(gt.resolution_m))
                                                          : k);
    }
    const std::vector<VoxelKey> predicted = OccupiedVoxelsOfClass(grid, options.semantic_class);
    std::vector<VoxelKey> shifted(predicted.size());
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          for (size_t i = 0; i < predicted.size(); ++i) {
            shifted[i] = VoxelKey{predicted[i].x + dx, predicted[i].y + dy, predicted[i].z + dz};
          }
          const double f1 = CompareVoxelSets(shifted, gt_keys, 0).f1;
          if (f1 > summary.best_shift_f1) {
            summary.best_shift_f1 = f1;
            summary.best_shift = VoxelKey{dx, dy, dz};
          }
        }
      }
    }
  }
  return summary;
}

std::string FormatMapCompare(const MapCompareSummary& s) {
  std::string out;
  const GroundTruthComparison& first = s.results.front();
  const auto describe = [](const MapSource& src) {
    return src.tree_type.empty()
               ? std::string(ToString(src.format))
               : fmt::format("{} {}", ToString(src.format), EscapeText(src.tree_type, 64));
  };
  out += fmt::format("map          {} ({}, {:g} mm voxels)\n", s.map.string(),
                     describe(s.map_source), first.map_resolution_m * 1000.0);
  if (s.gt_used_labels) {
    out += fmt::format("ground truth {} ({}, {:g} mm voxels, {} occupied voxels labelled {})\n",
                       s.gt.string(), describe(s.gt_source), first.gt_resolution_m * 1000.0,
                       first.gt_voxels_original, ToString(s.semantic_class));
  } else {
    out += fmt::format(
        "ground truth {} ({}, {:g} mm voxels, {} occupied voxels from {} leaves, {} of "
        "them pruned)\n",
        s.gt.string(), describe(s.gt_source), first.gt_resolution_m * 1000.0,
        first.gt_voxels_original, s.gt_occupied_leaves, s.gt_coarse_leaves);
  }
  out +=
      "lattice      both sides: voxel k covers [k s, (k + 1) s) on each axis (a corner at the "
      "origin)\n";
  if (!s.map_source.extension_note.empty()) {
    out += fmt::format("note         map: {}\n", s.map_source.extension_note);
  }
  if (!s.gt_source.extension_note.empty()) {
    out += fmt::format("note         ground truth: {}\n", s.gt_source.extension_note);
  }
  if (first.resampled) {
    out += fmt::format(
        "warning      resolutions differ (map {:g} mm, ground truth {:g} mm): GT voxel centres "
        "were mapped onto the map's {:g} mm lattice ({} GT voxels -> {}), so the exact scores "
        "also measure the resampling; for exact scores build the map at the GT's resolution "
        "(avp map build --voxel-size {:g})\n",
        first.map_resolution_m * 1000.0, first.gt_resolution_m * 1000.0,
        first.map_resolution_m * 1000.0, first.gt_voxels_original, first.ground_truth,
        first.gt_resolution_m);
  }
  out += fmt::format("predicted    {} occupied voxels labelled {}\n", first.predicted,
                     ToString(s.semantic_class));
  out += fmt::format("{:<12} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n", "tolerance", "TP", "FP",
                     "GT found", "FN", "precision", "recall", "F1");
  for (const GroundTruthComparison& r : s.results) {
    out += fmt::format("{:<12} {:>9} {:>9} {:>9} {:>9} {:>9.4f} {:>9.4f} {:>9.4f}\n",
                       r.tolerance_voxels == 0 ? std::string("exact")
                                               : fmt::format("+-{} voxel", r.tolerance_voxels),
                       r.tp, r.fp, r.gt_found, r.fn, r.precision, r.recall, r.f1);
  }
  if (first.predicted > 0 && first.ground_truth > 0) {
    out += fmt::format(
        "lattice check: the best one-voxel shift of the map, ({:+d}, {:+d}, {:+d}), gives exact "
        "F1 {:.4f} (unshifted {:.4f})\n",
        s.best_shift.x, s.best_shift.y, s.best_shift.z, s.best_shift_f1, first.f1);
    const GroundTruthComparison& last = s.results.back();
    if (last.tolerance_voxels > 0 && last.precision >= 0.95 && first.precision < 0.8) {
      out += fmt::format(
          "note         {:.0f} % of the predicted voxels lie within {} voxel(s) of the ground "
          "truth but only {:.0f} % on it: the two sides mark the same surfaces on different "
          "lattices or by different rules (resolution, a sub-voxel offset, solid vs surface); "
          "exact scores then measure that difference, tolerant ones the map (docs/evaluation.md, "
          "Comparing with another system's ground truth)\n",
          100.0 * last.precision, last.tolerance_voxels, 100.0 * first.precision);
    }
    if (s.best_shift_f1 >= first.f1 + 0.1) {
      out +=
          "warning      a one-voxel shift raises exact F1 by 0.1 or more: the two surfaces sit "
          "about a voxel apart (different frames, lattices or surface definitions); exact F1 "
          "is not comparable here, see docs/evaluation.md (Comparing with another system's "
          "ground truth)\n";
    }
  }
  out +=
      "TP: predicted voxels with a GT voxel within the tolerance (FP = predicted - TP); GT found: "
      "GT voxels with a predicted voxel within it (FN = GT - found). precision = TP / predicted, "
      "recall = found / GT.\n";
  return out;
}

nlohmann::json ToJson(const MapCompareSummary& s) {
  nlohmann::json results = nlohmann::json::array();
  for (const GroundTruthComparison& r : s.results) {
    results.push_back({{"tolerance_voxels", r.tolerance_voxels},
                       {"predicted", r.predicted},
                       {"ground_truth", r.ground_truth},
                       {"tp", r.tp},
                       {"fp", r.fp},
                       {"gt_found", r.gt_found},
                       {"fn", r.fn},
                       {"precision", r.precision},
                       {"recall", r.recall},
                       {"f1", r.f1}});
  }
  const GroundTruthComparison& first = s.results.front();
  return {{"map", s.map.string()},
          {"ground_truth", s.gt.string()},
          {"class", std::string(ToString(s.semantic_class))},
          {"map_resolution_m", first.map_resolution_m},
          {"gt_resolution_m", first.gt_resolution_m},
          {"resampled", first.resampled},
          {"gt_voxels_original", first.gt_voxels_original},
          {"gt_occupied_leaves", s.gt_occupied_leaves},
          {"gt_coarse_leaves", s.gt_coarse_leaves},
          {"map_format", std::string(ToString(s.map_source.format))},
          {"gt_format", std::string(ToString(s.gt_source.format))},
          {"gt_tree_type", s.gt_source.tree_type},
          {"gt_used_labels", s.gt_used_labels},
          {"best_one_voxel_shift", {s.best_shift.x, s.best_shift.y, s.best_shift.z}},
          {"best_one_voxel_shift_exact_f1", s.best_shift_f1},
          {"definitions",
           "tp: predicted voxels with a GT voxel within the tolerance cube; fp = predicted - tp; "
           "gt_found: GT voxels with a predicted voxel within it; fn = ground_truth - gt_found; "
           "precision = tp / predicted; recall = gt_found / ground_truth"},
          {"results", results}};
}

}  // namespace avp::mapping
