// avp.Map: any map file avp reads (.avpmap, .bt, .ot) as numpy arrays; compare, export.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/mapping/map_reader.h>
#include <avp/mapping/map_tools.h>
#include <avp/mapping/ply_export.h>

#include "bindings.h"

namespace avp::python {

namespace {

/// The voxels `which` names: "occupied", "labelled", "all-labelled" (ForEachExportedVoxel: the
/// PLY export's voxels, in its order) or "known" (every voxel with evidence, blocks in
/// allocation order). ValueError naming the others.
struct VoxelColumns {
  std::vector<double> x, y, z;
  std::vector<int32_t> i, j, k;
  std::vector<uint8_t> cls;
  std::vector<float> confidence;
  std::vector<uint16_t> instance, observations;
  std::vector<bool> occupied;
  std::vector<float> log_odds;

  void Reserve(size_t n) {
    for (auto* v : {&x, &y, &z}) v->reserve(n);
    for (auto* v : {&i, &j, &k}) v->reserve(n);
    cls.reserve(n);
    confidence.reserve(n);
    instance.reserve(n);
    observations.reserve(n);
    occupied.reserve(n);
    log_odds.reserve(n);
  }

  void Add(const mapping::OccupancyGrid& grid, const VoxelKey& key,
           const mapping::SemanticCell* cell, bool is_occupied, float lo) {
    const Eigen::Vector3d c = grid.CenterOf(key);
    x.push_back(c.x());
    y.push_back(c.y());
    z.push_back(c.z());
    i.push_back(key.x);
    j.push_back(key.y);
    k.push_back(key.z);
    const mapping::SemanticCell none;
    const mapping::SemanticCell& s = cell != nullptr && cell->has_label() ? *cell : none;
    cls.push_back(s.semantic_class);
    confidence.push_back(s.confidence);
    instance.push_back(s.instance_id);
    observations.push_back(s.observations);
    occupied.push_back(is_occupied);
    log_odds.push_back(lo);
  }

  py::dict ToDict() && {
    py::dict d;
    d["x"] = OwnedArray(std::move(x));
    d["y"] = OwnedArray(std::move(y));
    d["z"] = OwnedArray(std::move(z));
    d["i"] = OwnedArray(std::move(i));
    d["j"] = OwnedArray(std::move(j));
    d["k"] = OwnedArray(std::move(k));
    d["class"] = OwnedArray(std::move(cls));
    d["confidence"] = OwnedArray(std::move(confidence));
    d["instance"] = OwnedArray(std::move(instance));
    d["observations"] = OwnedArray(std::move(observations));
    py::array_t<bool> occ(static_cast<py::ssize_t>(occupied.size()));
    auto* o = occ.mutable_data();
    for (size_t n = 0; n < occupied.size(); ++n) o[n] = occupied[n];
    d["occupied"] = occ;
    d["log_odds"] = OwnedArray(std::move(log_odds));
    return d;
  }
};

constexpr std::array<std::string_view, 4> kVoxelSelections = {"occupied", "labelled",
                                                              "all-labelled", "known"};

VoxelColumns CollectVoxels(const mapping::OccupancyGrid& grid, const std::string& which) {
  VoxelColumns out;
  const float occupied = grid.occupied_log_odds();
  if (which == "known") {
    out.Reserve(grid.CountKnownVoxels());
    grid.ForEachBlock([&](const mapping::OccupancyBlock& b) {
      b.known.ForEachSet([&](int i) {
        const mapping::SemanticCell* cell = b.semantics != nullptr ? &(*b.semantics)[i] : nullptr;
        out.Add(grid, mapping::KeyOf(b.key, i), cell, b.log_odds[i] >= occupied, b.log_odds[i]);
      });
    });
    return out;
  }
  const std::optional<mapping::PlyVoxels> selection = mapping::PlyVoxelsFromString(which);
  if (!selection) {
    throw py::value_error(fmt::format("which {}: expected one of {}", QuoteText(which),
                                      fmt::join(kVoxelSelections, ", ")));
  }
  mapping::ForEachExportedVoxel(
      grid, *selection, [&](const VoxelKey& key, const mapping::SemanticCell* cell, bool occ) {
        out.Add(grid, key, cell, occ, grid.LogOdds(key).value_or(0.0f));
      });
  return out;
}

/// CollectVoxels of a map with the GIL released (its errors raised once it is held again).
VoxelColumns CollectVoxelsReleased(const PyMap& m, const std::string& which) {
  const mapping::OccupancyGrid& grid = m.map().grid();
  py::gil_scoped_release release;
  return CollectVoxels(grid, which);
}

SemanticClass ClassFromName(const std::string& name) {
  const std::optional<SemanticClass> c = SemanticClassFromString(name);
  if (!c) {
    std::vector<std::string> names;
    for (SemanticClass k : AllSemanticClasses()) names.emplace_back(ToString(k));
    throw py::value_error(
        fmt::format("class {}: expected one of {}", QuoteText(name), fmt::join(names, ", ")));
  }
  return *c;
}

py::dict ComparisonDict(const mapping::GroundTruthComparison& r) {
  py::dict d;
  d["tolerance_voxels"] = r.tolerance_voxels;
  d["precision"] = r.precision;
  d["recall"] = r.recall;
  d["f1"] = r.f1;
  d["tp"] = r.tp;
  d["fp"] = r.fp;
  d["fn"] = r.fn;
  d["predicted"] = r.predicted;
  d["ground_truth"] = r.ground_truth;
  d["gt_found"] = r.gt_found;
  d["resampled"] = r.resampled;
  return d;
}

std::shared_ptr<PyMap> LoadMap(const std::filesystem::path& path) {
  CheckFileExists(path, "map file");
  Result<mapping::LoadedMap> loaded = [&] {
    py::gil_scoped_release release;
    return mapping::LoadAnyMap(path);
  }();
  return std::make_shared<PyMap>(
      std::make_shared<const mapping::LoadedMap>(Unwrap(std::move(loaded))));
}

py::dict Compare(const PyMap& m, const py::object& gt, int tolerance_voxels,
                 const std::string& cls) {
  // The ground truth: another Map, or a map file.
  std::shared_ptr<PyMap> file_truth;
  if (!py::isinstance<PyMap>(gt)) file_truth = LoadMap(gt.cast<std::filesystem::path>());
  const PyMap& truth = file_truth != nullptr ? *file_truth : gt.cast<const PyMap&>();
  mapping::MapCompareOptions options;
  options.map = m.source().path;
  options.gt = truth.source().path;
  options.tolerance_voxels = tolerance_voxels;
  options.semantic_class = ClassFromName(cls);
  const mapping::SemanticMap& map = m.map();
  const mapping::SemanticMap& truth_map = truth.map();
  Result<mapping::MapCompareSummary> summary = [&] {
    py::gil_scoped_release release;
    return mapping::CompareMaps(map, m.source(), truth_map, truth.source(), options);
  }();
  const mapping::MapCompareSummary s = Unwrap(std::move(summary));
  py::dict d;
  d["exact"] = ComparisonDict(s.results.front());
  d["tolerance"] = s.results.size() > 1 ? py::object(ComparisonDict(s.results.back())) : py::none();
  d["gt_used_labels"] = s.gt_used_labels;
  d["best_shift"] = py::make_tuple(s.best_shift.x, s.best_shift.y, s.best_shift.z);
  d["best_shift_f1"] = s.best_shift_f1;
  return d;
}

py::dict Export(const PyMap& m, const std::filesystem::path& out, const std::string& format,
                const std::string& voxels, bool ascii) {
  mapping::MapExportOptions options;
  options.map = m.source().path;
  options.out = out;
  options.format = format;
  options.ply_ascii = ascii;
  const std::optional<mapping::PlyVoxels> v = mapping::PlyVoxelsFromString(voxels);
  if (!v) {
    throw py::value_error(
        fmt::format("voxels {}: expected labelled, all-labelled or occupied", QuoteText(voxels)));
  }
  options.ply_voxels = *v;
  const mapping::SemanticMap& map = m.map();
  Result<mapping::MapExportSummary> summary = [&] {
    py::gil_scoped_release release;
    return mapping::ExportMap(map, m.source(), options);
  }();
  const mapping::MapExportSummary s = Unwrap(std::move(summary));
  py::dict d;
  d["path"] = s.out;
  constexpr std::array<const char*, 4> kNames = {"bt", "ot", "ply", "avpmap"};
  d["format"] = kNames.at(static_cast<size_t>(s.format));
  d["occupied_voxels"] = s.occupied_voxels;
  d["labelled_voxels"] = s.labelled_voxels;
  d["file_bytes"] = s.file_bytes;
  return d;
}

py::list Instances(const PyMap& m) {
  py::list out;
  for (const mapping::InstanceInfo& i : m.map().Instances()) {
    py::dict d;
    d["id"] = i.id;
    d["class"] = std::string(ToString(i.semantic_class));
    d["voxels"] = i.voxels;
    d["centroid"] = py::make_tuple(i.centroid_W.x(), i.centroid_W.y(), i.centroid_W.z());
    d["mean_confidence"] = i.mean_confidence;
    out.append(d);
  }
  return out;
}

}  // namespace

const mapping::SemanticMap& PyMap::map() const {
  if (alive_ != nullptr && !*alive_) {
    throw std::runtime_error(
        "this map was handed to a planner for one plan() call, which is over: take the arrays "
        "you need (voxels(), centers()) during the call");
  }
  return *map_;
}

void BindMaps(py::module_& m) {
  py::class_<PyMap, std::shared_ptr<PyMap>>(
      m, "Map",
      "A semantic occupancy map read from any map file avp reads (.avpmap, .bt, .ot), as numpy "
      "arrays (docs/python.md).")
      .def_static("load", &LoadMap, py::arg("path"),
                  "Reads a map file; the format comes from its first bytes. Raises "
                  "FileNotFoundError, ValueError (corrupt or unknown), OSError.")
      .def_property_readonly(
          "path", [](const PyMap& l) { return l.source().path; },
          "The file it was read from; empty for the map a planner is handed.")
      .def_property_readonly(
          "format",
          [](const PyMap& l) {
            return l.borrowed() ? std::string("memory") : std::string(ToString(l.source().format));
          },
          "'avpmap', 'bt' or 'ot'; 'memory' for the map a planner is handed")
      .def_property_readonly("voxel_size_m", [](const PyMap& l) { return l.map().voxel_size_m(); })
      .def_property_readonly("has_labels", [](const PyMap& l) { return l.source().has_labels; })
      .def_property_readonly(
          "lost", [](const PyMap& l) { return l.source().lost; },
          "What the file cannot hold or reading it did not keep, one sentence each.")
      .def_property_readonly("occupied_voxels",
                             [](const PyMap& l) { return l.map().grid().CountOccupiedVoxels(); })
      .def_property_readonly("known_voxels",
                             [](const PyMap& l) { return l.map().grid().CountKnownVoxels(); })
      .def_property_readonly("labelled_voxels",
                             [](const PyMap& l) { return l.map().grid().CountSemanticVoxels(); })
      .def_property_readonly(
          "known_bounds", [](const PyMap& l) { return BoxArray(l.map().grid().KnownBounds()); },
          "The box around every known voxel, [[min x, y, z], [max x, y, z]] (metres).")
      .def(
          "voxels",
          [](const PyMap& l, const std::string& which) {
            return CollectVoxelsReleased(l, which).ToDict();
          },
          py::arg("which") = "occupied",
          "The voxels `which` names, as columns (a dict of 1-D arrays, pandas.DataFrame(...) "
          "takes it): x, y, z (voxel centre, m), i, j, k (voxel key), class, confidence, "
          "instance, observations, occupied, log_odds. which: 'occupied' (every occupied voxel), "
          "'labelled' (labelled and occupied), 'all-labelled' (every labelled voxel) -- the "
          "voxels and the order of `export(..., voxels=which)` to PLY -- or 'known' (every voxel "
          "with evidence, free ones too).")
      .def(
          "centers",
          [](const PyMap& l, const std::string& which) {
            const VoxelColumns c = CollectVoxelsReleased(l, which);
            std::vector<double> xyz;
            xyz.reserve(c.x.size() * 3);
            for (size_t n = 0; n < c.x.size(); ++n) xyz.insert(xyz.end(), {c.x[n], c.y[n], c.z[n]});
            return OwnedMatrix(std::move(xyz), 3);
          },
          py::arg("which") = "occupied", "The voxel centres of voxels(which) as an (n, 3) array.")
      .def("instances", &Instances,
           "The fruit instances: id, class, voxels, centroid, mean_confidence.")
      .def("compare", &Compare, py::arg("gt"), py::arg("tolerance_voxels") = 1,
           py::arg("cls") = "fruit",
           "Precision, recall, F1 and TP/FP/FN of this map's occupied voxels labelled `cls` "
           "against a ground truth (a Map or a map file: its voxels of `cls` when it carries "
           "labels, else all its occupied voxels), exactly and within `tolerance_voxels` (as "
           "`avp map compare`).")
      .def("export", &Export, py::arg("path"), py::arg("format") = "",
           py::arg("voxels") = "labelled", py::arg("ascii") = false,
           "Writes the map as .bt, .ot, .avpmap or .ply (format, or the extension of path), as "
           "`avp map export` does.")
      .def("__repr__", [](const PyMap& l) {
        return fmt::format("<avp.Map {} ({}), {} m voxels, {} occupied>", l.source().path.string(),
                           ToString(l.source().format), l.map().voxel_size_m(),
                           l.map().grid().CountOccupiedVoxels());
      });
}

}  // namespace avp::python
