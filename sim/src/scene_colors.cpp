// Colours of a loaded scene file: placeholder material colours replaced by class defaults
// (`materials: auto`), and the warnings about the scene as a whole (no fruit, a plant under the
// ground, classes a colour segmenter cannot tell apart).

#include <algorithm>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/text.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"

namespace avp::sim::internal {

std::string FormatColor(const Eigen::Vector3f& c) {
  return fmt::format("[{:.3g}, {:.3g}, {:.3g}]", c.x(), c.y(), c.z());
}

bool SameColor(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return (a - b).cwiseAbs().maxCoeff() <= 0.5f / 255.0f;
}

std::string NameList(const std::vector<std::string>& names) {
  std::vector<std::string> shown;
  for (size_t i = 0; i < names.size() && i < 3; ++i) shown.push_back(QuoteText(names[i], 80));
  std::string out = fmt::format("{}", fmt::join(shown, ", "));
  if (names.size() > 3) out += fmt::format(" and {} more", names.size() - 3);
  return out;
}

namespace {

/// A class whose default colour has a hue: an achromatic material colour shared by all its parts
/// is taken for a placeholder under `materials: auto`.
bool ChromaticClass(SemanticClass c) { return !IsAchromatic(DefaultClassColor(c)); }

/// One placeholder warning per (materials, colour): the usual single placeholder material is one
/// sentence naming every class it was replaced in.
struct PlaceholderGroup {
  std::string materials;
  Eigen::Vector3f color;
  std::vector<std::string> classes;  // "fruit (25 parts)"
};

/// The parts of class `c` whose colour comes from their material.
std::vector<ImportedPart*> PartsColoredByMaterial(std::vector<ImportedPart>& parts,
                                                  SemanticClass c) {
  std::vector<ImportedPart*> from_material;
  for (ImportedPart& part : parts) {
    if (part.semantic_class == c && part.color_source == ColorSource::kMaterial) {
      from_material.push_back(&part);
    }
  }
  return from_material;
}

/// When the parts of class `c` coloured by their material all have one achromatic colour: they
/// get the class default, and `groups` learns of it.
void ReplaceClassPlaceholder(SemanticClass c, std::vector<ImportedPart>& parts,
                             std::vector<PlaceholderGroup>& groups) {
  const std::vector<ImportedPart*> from_material = PartsColoredByMaterial(parts, c);
  if (from_material.empty()) return;
  const Eigen::Vector3f color = from_material.front()->albedo;
  if (!IsAchromatic(color)) return;
  if (!std::all_of(from_material.begin(), from_material.end(),
                   [&](const ImportedPart* p) { return SameColor(p->albedo, color); })) {
    return;
  }
  std::vector<std::string> materials;
  for (ImportedPart* part : from_material) {
    if (std::find(materials.begin(), materials.end(), part->material) == materials.end()) {
      materials.push_back(part->material);
    }
    part->material_color = part->albedo;
    part->albedo = DefaultClassColor(c);
    part->color_source = ColorSource::kPlaceholder;
  }
  const std::string names = NameList(materials);
  const std::string what =
      fmt::format("{} ({} part{}, now {})", ToString(c), from_material.size(),
                  from_material.size() == 1 ? "" : "s", FormatColor(DefaultClassColor(c)));
  auto it = std::find_if(groups.begin(), groups.end(), [&](const PlaceholderGroup& g) {
    return g.materials == names && SameColor(g.color, color);
  });
  if (it == groups.end()) {
    groups.push_back({names, color, {what}});
  } else {
    it->classes.push_back(what);
  }
}

/// The distinct colours of one class's objects, and how many objects it has.
struct ClassColors {
  SemanticClass semantic_class;
  std::vector<Eigen::Vector3f> colors;
  size_t parts = 0;
};

/// Every class but background with its colours, in class order (fruit first), whatever the order
/// of the objects. A textured object counts with its albedo, the texture's mean over it.
std::vector<ClassColors> ColorsByClass(const Scene& scene) {
  std::vector<ClassColors> classes;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kBackground) continue;
    auto it = std::find_if(classes.begin(), classes.end(), [&](const ClassColors& c) {
      return c.semantic_class == o.semantic_class;
    });
    if (it == classes.end()) {
      classes.push_back({o.semantic_class, {}, 0});
      it = std::prev(classes.end());
    }
    ++it->parts;
    if (std::none_of(it->colors.begin(), it->colors.end(),
                     [&](const Eigen::Vector3f& c) { return SameColor(c, o.albedo); })) {
      it->colors.push_back(o.albedo);
    }
  }
  std::sort(classes.begin(), classes.end(), [](const ClassColors& a, const ClassColors& b) {
    return a.semantic_class < b.semantic_class;
  });
  return classes;
}

/// A plant under the ground (or under the robot base's plane when there is none) is almost
/// always a wrong up axis, unit or pose.
void WarnPlantBelowGround(const Scene& scene, const std::vector<const SceneObject*>& plant,
                          std::vector<std::string>& warnings) {
  double ground_z = 0.0;
  bool has_ground = false;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kGround) {
      ground_z = o.Bounds().max().z();
      has_ground = true;
    }
  }
  Box3 plant_box;
  for (const SceneObject* o : plant) plant_box.Extend(o->Bounds());
  constexpr double kBelowGroundToleranceM = 0.01;
  if (!plant_box.IsEmpty() && plant_box.min().z() < ground_z - kBelowGroundToleranceM) {
    warnings.push_back(fmt::format(
        "the plant reaches z = {:.3f} m, {:.3f} m below the {} at z = {:.3f} m (its extent is "
        "{:.3f} x {:.3f} x {:.3f} m in x, y, z): check the mesh's up axis (up_axis), units "
        "(scale) and pose",
        plant_box.min().z(), ground_z - plant_box.min().z(),
        has_ground ? "ground" : "robot base plane", ground_z, plant_box.size().x(),
        plant_box.size().y(), plant_box.size().z()));
  }
}

/// When the whole plant (two parts or more) is one colour: a warning; returns whether it is.
bool WarnOneColorPlant(const std::vector<const SceneObject*>& plant,
                       const std::vector<ClassColors>& classes,
                       std::vector<std::string>& warnings) {
  const bool one_color_plant =
      plant.size() >= 2 && std::all_of(plant.begin(), plant.end(), [&](const SceneObject* o) {
        return SameColor(o->albedo, plant.front()->albedo);
      });
  if (!one_color_plant) return false;
  std::vector<std::string> names;
  for (const ClassColors& c : classes) {
    if (c.semantic_class != SemanticClass::kGround) names.emplace_back(ToString(c.semantic_class));
  }
  warnings.push_back(fmt::format(
      "the whole plant ({} parts, classes {}) is one colour {}: a colour segmenter cannot find "
      "fruit in it (give the class rules colours, or check 'materials:')",
      plant.size(), fmt::join(names, ", "), FormatColor(plant.front()->albedo)));
  return true;
}

/// Classes a colour segmenter cannot tell apart: every part of one class has a colour another
/// class has too (within the plant only when the one-colour-plant warning said so already).
void WarnIndistinguishableClasses(const std::vector<ClassColors>& classes, bool one_color_plant,
                                  std::vector<std::string>& warnings) {
  std::vector<std::pair<SemanticClass, SemanticClass>> reported;
  for (size_t a = 0; a < classes.size(); ++a) {
    if (classes[a].colors.size() != 1) continue;
    const Eigen::Vector3f& color = classes[a].colors.front();
    for (size_t b = 0; b < classes.size(); ++b) {
      if (b == a) continue;
      const SemanticClass ca = classes[a].semantic_class;
      const SemanticClass cb = classes[b].semantic_class;
      if (one_color_plant && ca != SemanticClass::kGround && cb != SemanticClass::kGround) continue;
      if (std::find(reported.begin(), reported.end(), std::make_pair(cb, ca)) != reported.end()) {
        continue;
      }
      if (std::none_of(classes[b].colors.begin(), classes[b].colors.end(),
                       [&](const Eigen::Vector3f& c) { return SameColor(c, color); })) {
        continue;
      }
      reported.emplace_back(ca, cb);
      warnings.push_back(fmt::format(
          "every {} part ({}) is {}, a colour {} parts have too: a colour segmenter cannot tell "
          "{} from {} (give the class rules colours, or check 'materials:')",
          ToString(ca), classes[a].parts, FormatColor(color), ToString(cb), ToString(ca),
          ToString(cb)));
    }
  }
}

}  // namespace

void ReplacePlaceholderColors(const MeshEntry& entry, const std::string& context,
                              std::vector<ImportedPart>& parts,
                              std::vector<std::string>& warnings) {
  if (entry.materials != MaterialMode::kAuto) return;
  std::vector<PlaceholderGroup> groups;
  for (const SemanticClass c : AllSemanticClasses()) {
    if (ChromaticClass(c)) ReplaceClassPlaceholder(c, parts, groups);
  }
  for (const PlaceholderGroup& g : groups) {
    warnings.push_back(fmt::format(
        "{} ({}): material {} colour {} looks like a placeholder (every part of the class coloured "
        "by its material has this one achromatic colour), replaced by the class default in {} "
        "('materials: use' keeps the material colour, a class rule's 'color' sets another)",
        context, QuoteText(entry.file_text, 80), g.materials, FormatColor(g.color),
        fmt::join(g.classes, ", ")));
  }
}

void SceneWarnings(const Scene& scene, std::vector<std::string>& warnings) {
  size_t fruits = 0;
  std::vector<const SceneObject*> plant;
  for (const SceneObject& o : scene.objects) {
    if (o.semantic_class == SemanticClass::kFruit) ++fruits;
    if (o.semantic_class == SemanticClass::kBackground) continue;
    if (o.semantic_class != SemanticClass::kGround) plant.push_back(&o);
  }
  const std::vector<ClassColors> classes = ColorsByClass(scene);
  WarnPlantBelowGround(scene, plant, warnings);
  if (fruits == 0) {
    warnings.push_back(
        "no part is of class fruit: the scene has no fruit ground truth (check the class rules "
        "with 'avp scene check FILE')");
  }
  const bool one_color_plant = WarnOneColorPlant(plant, classes, warnings);
  WarnIndistinguishableClasses(classes, one_color_plant, warnings);
}

}  // namespace avp::sim::internal
