#include <chrono>
#include <cmath>
#include <map>
#include <memory>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/apps/render_command.h>
#include <avp/apps/scene_command.h>
#include <avp/core/rng.h>
#include <avp/io/depth.h>
#include <avp/io/file.h>
#include <avp/io/json.h>
#include <avp/io/label_preview.h>
#include <avp/io/png.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/sensor_noise.h>

#include "cli_common.h"

namespace avp::apps {

namespace {

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

/// Every file RunRender writes into its folder.
constexpr const char* kRenderFiles[] = {"rgb.png",    "depth.png",          "instance.png",
                                        "class.png",  "labels_preview.png", "camera.json",
                                        "fruits.json"};

Result<robot::ArmModel> LoadArm(const std::filesystem::path& config) {
  if (config.empty()) return robot::LoadDefaultArm();
  return robot::LoadArm(config);
}

}  // namespace

Result<RenderSummary> RunRender(const RenderOptions& options,
                                const sim::ScenarioRegistry& scenarios) {
  AVP_RETURN_IF_ERROR(options.intrinsics.Validate());
  if (options.joints_deg && options.camera_pose) {
    return InvalidArgumentError("give either --joints or --camera-pose, not both");
  }
  // Outputs never overwrite inputs: none of the files written may be the scene or the arm config.
  for (const char* name : kRenderFiles) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / name, "render output",
                                                  options.scene.scene_file, "scene file"));
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / name, "render output",
                                                  options.arm_config, "arm config"));
  }
  AVP_ASSIGN_OR_RETURN(const sim::Scene scene, sim::LoadScene(options.scene, scenarios));
  LogSceneWarnings(scene);

  RenderSummary summary;
  if (options.camera_pose) {
    AVP_ASSIGN_OR_RETURN(summary.X_WC, PoseFromVector(*options.camera_pose));
  } else {
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
      q = Eigen::Map<const Eigen::VectorXd>(
          scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
    } else {
      return InvalidArgumentError(fmt::format(
          "scene '{}' has no start joints: give --joints or --camera-pose", scene.name));
    }
    AVP_RETURN_IF_ERROR(arm.CheckJoints(q));
    summary.X_WC = arm.CameraPose(q);
    for (Eigen::Index i = 0; i < q.size(); ++i) summary.joints_deg.push_back(RadToDeg(q[i]));
  }

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

  // Per-fruit visible pixel counts.
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
  const std::vector<sim::FruitTruth> fruits = scene.Fruits();
  summary.total_fruits = fruits.size();
  summary.visible_fruits = fruit_pixels.size();

  const std::filesystem::path& dir = options.out_dir;
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
  AVP_RETURN_IF_ERROR(write("camera.json", io::WriteJsonFile(dir / "camera.json", camera)));

  nlohmann::json fruits_json = nlohmann::json::array();
  for (const sim::FruitTruth& f : fruits) {
    const auto it = fruit_pixels.find(f.instance_id);
    fruits_json.push_back({{"instance_id", f.instance_id},
                           {"name", f.name},
                           {"center_m", {f.center_W.x(), f.center_W.y(), f.center_W.z()}},
                           {"radii_m", {f.radii.x(), f.radii.y(), f.radii.z()}},
                           {"visible_pixels", it == fruit_pixels.end() ? 0 : it->second}});
  }
  AVP_RETURN_IF_ERROR(
      write("fruits.json", io::WriteJsonFile(dir / "fruits.json", {{"fruits", fruits_json}})));
  return summary;
}

namespace {

int RenderAndReport(const RenderOptions& options, const sim::ScenarioRegistry& scenarios) {
  const auto result = RunRender(options, scenarios);
  if (!result.ok()) return Failed("render", result.status());
  const auto& s = *result;
  spdlog::info("camera X_WC: {}", s.X_WC.ToString());
  spdlog::info("rendered {}x{} in {:.1f} ms ({} triangles); valid depth on {} pixels",
               options.intrinsics.width, options.intrinsics.height, s.render_ms, s.num_triangles,
               s.valid_depth_pixels);
  spdlog::info("fruit pixels: {} ({} of {} fruits visible)", s.fruit_pixels, s.visible_fruits,
               s.total_fruits);
  std::printf("wrote %zu files to %s:\n", s.files.size(), options.out_dir.string().c_str());
  for (const auto& f : s.files) std::printf("  %s\n", f.string().c_str());
  return 0;
}

struct RenderCli {
  RenderOptions options;
  std::vector<double> joints;
  std::vector<double> pose;
  std::string out_dir = RenderOptions{}.out_dir.string();
  std::string scene_file;
  std::string arm_config;
  CLI::Option* joints_opt = nullptr;
  CLI::Option* pose_opt = nullptr;
};

}  // namespace

void AddRenderCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<RenderCli>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render one simulated RGB-D + label view and write it to a folder");
  cmd->add_option("--scenario", cli->options.scene.scenario,
                  "Built-in scenario name (see `avp scenes`); default: " +
                      std::string(sim::DefaultScenarioName()));
  cmd->add_option("--scene", cli->scene_file, "YAML scene file (docs/scene-format.md)");
  AddArrangementOption(*cmd, cli->options.scene.arrangement);
  AddNumberOption(*cmd, "--seed", cli->options.scene.seed, uint64_t{0}, MaxOf<uint64_t>(),
                  "Seed of the procedural plant and the noise");
  cli->joints_opt = cmd->add_option("--joints", cli->joints,
                                    "Arm joint angles in degrees, comma separated, e.g. "
                                    "--joints=0,-70,60,0,47.5,0 (default: the scene's start)")
                        ->delimiter(',')
                        ->allow_extra_args(false);
  cli->pose_opt = cmd->add_option("--camera-pose", cli->pose,
                                  "Camera optical frame pose in the robot base frame: "
                                  "x,y,z (m),roll,pitch,yaw (deg)")
                      ->delimiter(',')
                      ->allow_extra_args(false);
  cli->joints_opt->excludes(cli->pose_opt);
  cmd->add_option("--arm", cli->arm_config,
                  "Arm config YAML (default: configs/arms/igus_rebel_d435.yaml)");
  cmd->add_flag("--noise", cli->options.noise, "Apply the seeded D435-like depth noise model");
  cmd->add_option("--out", cli->out_dir, "Output folder")->default_val(cli->out_dir);
  cmd->callback([cli, &context] {
    RunGuarded(context, [&] {
      RenderOptions o = cli->options;
      o.scene.scene_file = cli->scene_file;
      o.arm_config = cli->arm_config;
      o.out_dir = cli->out_dir;
      if (cli->joints_opt->count() > 0) o.joints_deg = cli->joints;
      if (cli->pose_opt->count() > 0) o.camera_pose = cli->pose;
      return RenderAndReport(o, context.registries->scenarios);
    });
  });
}

}  // namespace avp::apps
