// Fuzz target: the scene file loader (sim/scene_file.h LoadSceneFile) on any YAML. The loader
// takes a path, so the input is written to <scratch>/scene.yaml beside two fixed meshes it may
// name: plant.obj (objects stem, leaf_1, fruit_1, fruit_2) and fruit.ply (one tetrahedron).
//
// An input may also bring a mesh file of its own: everything after a line "#@file NAME" (NAME of
// [a-z0-9_.], at most 32 characters, e.g. "#@file m.ply") is written to <scratch>/NAME, so the
// fuzzer reaches the mesh importers (assimp) and the checks on what they return.
// Property: a scene that loads passes Scene::Validate().

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <avp/sim/scene_file.h>

#include "fuzz_target.h"

namespace {

constexpr std::string_view kPlantObj =
    "o stem\nv 0 0 0\nv 0.01 0 0\nv 0 0 0.5\nf 1 2 3\n"
    "o leaf_1\nv 0 0 0.3\nv 0.1 0 0.3\nv 0.1 0.05 0.3\nf 4 5 6\n"
    "o fruit_1\nv 0.05 0 0.2\nv 0.07 0 0.2\nv 0.06 0.02 0.2\nv 0.06 0.01 0.22\n"
    "f 7 8 9\nf 7 8 10\nf 8 9 10\nf 7 9 10\n"
    "o fruit_2\nv 0.05 0 0.1\nv 0.07 0 0.1\nv 0.06 0.02 0.1\nf 11 12 13\n";

constexpr std::string_view kFruitPly =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n0.02 0 0\n0 0.02 0\n0 0 0.02\n3 0 1 2\n3 0 1 3\n3 1 2 3\n3 0 2 3\n";

bool GoodName(std::string_view name) {
  if (name.empty() || name.size() > 32 || name == "scene.yaml" || name == "." || name == "..") {
    return false;
  }
  for (char c : name) {
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.')) return false;
  }
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::filesystem::path dir = avp::fuzz::ScratchDir() / "scene";
  static const bool ready = [&] {
    std::filesystem::create_directories(dir);
    avp::fuzz::WriteFile(dir / "plant.obj", kPlantObj);
    avp::fuzz::WriteFile(dir / "fruit.ply", kFruitPly);
    return true;
  }();
  (void)ready;

  std::string_view yaml(reinterpret_cast<const char*>(data), size);
  std::string extra_name;
  constexpr std::string_view kMarker = "#@file ";
  size_t at = yaml.starts_with(kMarker) ? 0 : yaml.find(std::string("\n") + std::string(kMarker));
  if (at != std::string_view::npos) {
    const size_t name_begin = at + (at == 0 && yaml.starts_with(kMarker) ? 0 : 1) + kMarker.size();
    const size_t eol = yaml.find('\n', name_begin);
    if (eol != std::string_view::npos) {
      const std::string_view name = yaml.substr(name_begin, eol - name_begin);
      if (GoodName(name)) {
        extra_name = std::string(name);
        avp::fuzz::WriteFile(dir / extra_name, yaml.substr(eol + 1));
        yaml = yaml.substr(0, at);
      }
    }
  }
  avp::fuzz::WriteFile(dir / "scene.yaml", yaml);
  avp::Result<avp::sim::Scene> scene = avp::sim::LoadSceneFile(dir / "scene.yaml");
  if (scene.ok()) {
    avp::Status valid = scene->Validate();
    if (!valid.ok()) avp::fuzz::Fail("a loaded scene does not validate: " + valid.ToString());
  }
  if (!extra_name.empty()) {
    std::error_code ignored;
    std::filesystem::remove(dir / extra_name, ignored);
  }
  return 0;
}
