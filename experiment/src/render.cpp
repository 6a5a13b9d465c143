#include <chrono>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include <avp/core/rng.h>
#include <avp/core/semantic_class.h>
#include <avp/experiment/output_folder.h>
#include <avp/experiment/render.h>
#include <avp/io/depth.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/io/label_preview.h>
#include <avp/io/png.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/sensor_noise.h>

namespace avp::experiment {

namespace {

namespace fs = std::filesystem;

Result<RigidTransform> PoseFromVector(const std::vector<double>& v) {
  if (v.size() != 6) {
    return InvalidArgumentError(
        fmt::format("--camera-pose needs 6 numbers x,y,z (m),roll,pitch,yaw (deg); got {}: [{}]",
                    v.size(), fmt::join(v, ", ")));
  }
  for (double x : v) {
    if (!std::isfinite(x)) {
      return InvalidArgumentError(
          fmt::format("--camera-pose has a non-finite value: [{}]", fmt::join(v, ", ")));
    }
  }
  return RigidTransform::FromRpy(DegToRad(v[3]), DegToRad(v[4]), DegToRad(v[5]),
                                 Eigen::Vector3d(v[0], v[1], v[2]));
}

/// Every file RenderToFolder writes into its folder.
constexpr const char* kRenderFiles[] = {"rgb.png",    "depth.png",          "instance.png",
                                        "class.png",  "labels_preview.png", "camera.json",
                                        "fruits.json"};

Result<robot::ArmModel> LoadArm(const fs::path& config) {
  if (config.empty()) return robot::LoadDefaultArm();
  return robot::LoadArm(config);
}

/// Outputs never overwrite inputs: none of the files written may be the scene or the arm config.
Status CheckOptions(const RenderOptions& options) {
  AVP_RETURN_IF_ERROR(options.intrinsics.Validate());
  if (options.joints_deg && options.camera_pose) {
    return InvalidArgumentError("give either --joints or --camera-pose, not both");
  }
  for (const char* name : kRenderFiles) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / name, "render output",
                                                  options.scene.scene_file, "scene file"));
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / name, "render output",
                                                  options.arm_config, "arm config"));
  }
  return Status::Ok();
}

/// The camera pose: given directly, or FK of the given joints or of the scene's start joints
/// (then summary.joints_deg holds the joints).
Status CameraPose(const RenderOptions& options, const sim::Scene& scene, RenderSummary& summary) {
  if (options.camera_pose) {
    AVP_ASSIGN_OR_RETURN(summary.X_WC, PoseFromVector(*options.camera_pose));
    return Status::Ok();
  }
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm, LoadArm(options.arm_config));
  Eigen::VectorXd q;
  if (options.joints_deg) {
    const auto& j = *options.joints_deg;
    if (static_cast<int>(j.size()) != arm.num_joints()) {
      return InvalidArgumentError(fmt::format("--joints needs {} values (degrees), got {}: [{}]",
                                              arm.num_joints(), j.size(), fmt::join(j, ", ")));
    }
    q = Eigen::Map<const Eigen::VectorXd>(j.data(), static_cast<Eigen::Index>(j.size())) *
        (EIGEN_PI / 180.0);
  } else if (!scene.start_joints_rad.empty()) {
    q = Eigen::Map<const Eigen::VectorXd>(scene.start_joints_rad.data(),
                                          static_cast<Eigen::Index>(scene.start_joints_rad.size()));
  } else {
    return InvalidArgumentError(
        fmt::format("scene '{}' has no start joints: give --joints or --camera-pose", scene.name));
  }
  AVP_RETURN_IF_ERROR(arm.CheckJoints(q));
  summary.X_WC = arm.CameraPose(q);
  for (Eigen::Index i = 0; i < q.size(); ++i) summary.joints_deg.push_back(RadToDeg(q[i]));
  return Status::Ok();
}

/// Pixel counts of the frame: valid depth, fruit, and per fruit instance (returned).
std::map<uint16_t, size_t> CountPixels(const sim::RenderedFrame& frame, RenderSummary& summary) {
  std::map<uint16_t, size_t> fruit_pixels;
  const auto classes = frame.class_ids.data();
  const auto instances = frame.instance_ids.data();
  const auto depth = frame.rgbd.depth_m.data();
  for (size_t i = 0; i < classes.size(); ++i) {
    if (IsValidDepth(depth[i])) ++summary.valid_depth_pixels;
    if (classes[i] == static_cast<uint8_t>(SemanticClass::kFruit)) {
      ++fruit_pixels[instances[i]];
      ++summary.fruit_pixels;
    }
  }
  return fruit_pixels;
}

/// camera.json: the intrinsics, the pose, the conventions of the files and what was rendered.
nlohmann::json CameraJson(const RenderOptions& options, const sim::Scene& scene,
                          const RenderSummary& summary) {
  nlohmann::json classes_json = nlohmann::json::object();
  for (SemanticClass c : AllSemanticClasses()) {
    classes_json[std::string(ToString(c))] = static_cast<int>(c);
  }
  nlohmann::json camera = {
      {"intrinsics", io::ToJson(options.intrinsics)},
      {"X_WC", io::ToJson(summary.X_WC)},
      {"world_frame", "robot base_link: x forward, y left, z up"},
      {"camera_frame", "optical: x right, y down, z forward"},
      {"depth",
       {{"file", "depth.png"}, {"unit", "millimetre"}, {"invalid", 0}, {"type", "z-depth"}}},
      {"labels",
       {{"instance_file", "instance.png"}, {"class_file", "class.png"}, {"classes", classes_json}}},
      {"scene",
       {{"name", scene.name},
        {"seed", options.scene.seed},
        {"arrangement", options.scene.arrangement}}},
      {"noise", options.noise},
  };
  if (!summary.joints_deg.empty()) camera["joints_deg"] = summary.joints_deg;
  return camera;
}

/// fruits.json: every ground-truth fruit with its visible pixels in this view.
nlohmann::json FruitsJson(const std::vector<sim::FruitTruth>& fruits,
                          const std::map<uint16_t, size_t>& fruit_pixels) {
  nlohmann::json fruits_json = nlohmann::json::array();
  for (const sim::FruitTruth& f : fruits) {
    const auto it = fruit_pixels.find(f.instance_id);
    fruits_json.push_back({{"instance_id", f.instance_id},
                           {"name", f.name},
                           {"center_m", {f.center_W.x(), f.center_W.y(), f.center_W.z()}},
                           {"radii_m", {f.radii.x(), f.radii.y(), f.radii.z()}},
                           {"visible_pixels", it == fruit_pixels.end() ? 0 : it->second}});
  }
  return {{"fruits", fruits_json}};
}

/// Writes the images and the two JSON files into options.out_dir, listing them in summary.files.
Status WriteRenderFiles(const RenderOptions& options, const sim::Scene& scene,
                        const sim::RenderedFrame& frame,
                        const std::map<uint16_t, size_t>& fruit_pixels, RenderSummary& summary) {
  const fs::path& dir = options.out_dir;
  auto write = [&](const std::string& name, const Status& status) -> Status {
    AVP_RETURN_IF_ERROR(status);
    summary.files.push_back(dir / name);
    return Status::Ok();
  };
  AVP_RETURN_IF_ERROR(write("rgb.png", io::WritePngRgb8(dir / "rgb.png", frame.rgbd.rgb)));
  AVP_RETURN_IF_ERROR(
      write("depth.png",
            io::WritePngGray16(dir / "depth.png", io::DepthToMillimetres(frame.rgbd.depth_m))));
  AVP_RETURN_IF_ERROR(
      write("instance.png", io::WritePngGray16(dir / "instance.png", frame.instance_ids)));
  AVP_RETURN_IF_ERROR(write("class.png", io::WritePngGray8(dir / "class.png", frame.class_ids)));
  AVP_RETURN_IF_ERROR(write(
      "labels_preview.png",
      io::WritePngRgb8(dir / "labels_preview.png",
                       io::ColorizeLabels(frame.instance_ids, frame.class_ids, frame.rgbd.rgb))));
  AVP_RETURN_IF_ERROR(write(
      "camera.json", io::WriteJsonFile(dir / "camera.json", CameraJson(options, scene, summary))));
  return write("fruits.json",
               io::WriteJsonFile(dir / "fruits.json", FruitsJson(scene.Fruits(), fruit_pixels)));
}

}  // namespace

Result<RenderSummary> RenderToFolder(const RenderOptions& options,
                                     const sim::ScenarioRegistry& scenarios) {
  AVP_RETURN_IF_ERROR(CheckOptions(options));
  AVP_RETURN_IF_ERROR(CheckOutputFolder(options.out_dir, RenderFolderKind(), options.force));
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  if (options.on_scene) options.on_scene(scene);
  RenderSummary summary;
  AVP_RETURN_IF_ERROR(CameraPose(options, scene, summary));

  const sim::RgbdRenderer renderer(scene);
  const auto t0 = std::chrono::steady_clock::now();
  sim::RenderedFrame frame = renderer.Render(options.intrinsics, summary.X_WC);
  summary.render_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (options.noise) {
    sim::DepthNoiseConfig noise;
    noise.enabled = true;
    Rng rng = Rng(options.scene.seed).Fork("render-noise");
    sim::ApplyDepthNoise(noise, frame, rng);
  }
  summary.num_triangles = renderer.num_triangles();
  const std::map<uint16_t, size_t> fruit_pixels = CountPixels(frame, summary);
  summary.total_fruits = scene.Fruits().size();
  summary.visible_fruits = fruit_pixels.size();
  AVP_RETURN_IF_ERROR(PrepareOutputFolder(options.out_dir, RenderFolderKind(), options.force));
  AVP_RETURN_IF_ERROR(MarkInProgress(options.out_dir, RenderFolderKind(), "avp render"));
  if (Status s = WriteRenderFiles(options, scene, frame, fruit_pixels, summary); !s.ok()) {
    MarkFailed(options.out_dir, RenderFolderKind(), "avp render", s);
    return s;
  }
  AVP_RETURN_IF_ERROR(MarkComplete(options.out_dir, RenderFolderKind(), "avp render"));
  return summary;
}

}  // namespace avp::experiment
