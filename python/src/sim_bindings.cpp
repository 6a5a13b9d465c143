// avp.Scene, avp.Camera, avp.Arm: built-in scenarios and scene files, renders as numpy, the arm's
// kinematics.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/core/segmentation.h>
#include <avp/core/semantic_class.h>
#include <avp/core/simulator_labels.h>
#include <avp/io/image_limits.h>
#include <avp/robot/arm_model.h>
#include <avp/segmentation/segment_image.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene.h>
#include <avp/sim/sensor_noise.h>

#include "bindings.h"

namespace avp::python {

namespace {

/// A scene and its renderer, built on the first render (building copies the geometry into a BVH).
struct PyScene {
  sim::Scene scene;
  std::unique_ptr<sim::RgbdRenderer> renderer;

  const sim::RgbdRenderer& Renderer() {
    if (renderer == nullptr) renderer = std::make_unique<sim::RgbdRenderer>(scene);
    return *renderer;
  }
};

/// A joint vector: a 1-D float64 array (or a list) of the arm's joint count.
Eigen::VectorXd JointsFrom(const py::handle& value, const robot::ArmModel& arm) {
  const py::array a = CheckedArray(py::isinstance<py::array>(value)
                                       ? py::reinterpret_borrow<py::object>(value)
                                       : py::object(py::array_t<double>(value.cast<py::list>())),
                                   "joints", py::dtype::of<double>(), {arm.num_joints()});
  const auto* d = static_cast<const double*>(a.data());
  Eigen::VectorXd q(arm.num_joints());
  for (int i = 0; i < arm.num_joints(); ++i) q[i] = d[i];
  return q;
}

/// JointsFrom, within the arm's limits (ValueError naming the joint otherwise).
Eigen::VectorXd JointsWithinLimits(const py::handle& value, const robot::ArmModel& arm) {
  Eigen::VectorXd q = JointsFrom(value, arm);
  ThrowIfError(arm.CheckJoints(q));
  return q;
}

py::array_t<double> VectorArray(const Eigen::VectorXd& v) {
  return OwnedArray(std::vector<double>(v.data(), v.data() + v.size()));
}

std::shared_ptr<PyScene> MakeScene(const std::string& scenario,
                                   const std::optional<std::filesystem::path>& scene_file,
                                   uint64_t seed, const std::string& arrangement) {
  if (scene_file) CheckFileExists(*scene_file, "scene file");
  sim::SceneSource source{scenario, scene_file.value_or(""), seed, arrangement};
  if (source.scenario.empty() && source.scene_file.empty()) {
    source.scenario = std::string(sim::DefaultScenarioName());
  }
  Result<sim::Scene> scene = [&] {
    py::gil_scoped_release release;
    return sim::LoadScene(source, ProgramRegistries().scenarios);
  }();
  auto out = std::make_shared<PyScene>();
  out->scene = Unwrap(std::move(scene));
  return out;
}

py::dict Fruits(const sim::Scene& scene) {
  std::vector<uint16_t> ids;
  std::vector<double> x, y, z, rx, ry, rz;
  for (const sim::FruitTruth& f : scene.Fruits()) {
    ids.push_back(f.instance_id);
    x.push_back(f.center_W.x());
    y.push_back(f.center_W.y());
    z.push_back(f.center_W.z());
    rx.push_back(f.radii.x());
    ry.push_back(f.radii.y());
    rz.push_back(f.radii.z());
  }
  py::dict d;
  d["instance"] = OwnedArray(std::move(ids));
  d["x"] = OwnedArray(std::move(x));
  d["y"] = OwnedArray(std::move(y));
  d["z"] = OwnedArray(std::move(z));
  d["radius_x"] = OwnedArray(std::move(rx));
  d["radius_y"] = OwnedArray(std::move(ry));
  d["radius_z"] = OwnedArray(std::move(rz));
  return d;
}

std::shared_ptr<robot::ArmModel> LoadArmModel(const std::optional<std::filesystem::path>& path) {
  if (path) {
    CheckFileExists(*path, "arm configuration");
    return std::make_shared<robot::ArmModel>(Unwrap(robot::LoadArm(*path)));
  }
  // The default arm, read once (an ArmModel is immutable and safe to share between threads).
  static const std::shared_ptr<robot::ArmModel> default_arm =
      std::make_shared<robot::ArmModel>(Unwrap(robot::LoadDefaultArm()));
  return default_arm;
}

/// The camera pose of a render: `camera_pose` (4x4), or the camera of `joints` on `arm` (the
/// default arm when None), or the scene's start joints.
RigidTransform RenderPose(const sim::Scene& scene, const py::object& camera_pose,
                          const py::object& joints, const py::object& arm_object) {
  if (!camera_pose.is_none() && !joints.is_none()) {
    throw py::value_error("give camera_pose or joints, not both");
  }
  if (!camera_pose.is_none()) return TransformFromArray(camera_pose, "camera_pose");
  const std::shared_ptr<robot::ArmModel> arm =
      arm_object.is_none() ? LoadArmModel(std::nullopt)
                           : arm_object.cast<std::shared_ptr<robot::ArmModel>>();
  Eigen::VectorXd q;
  if (!joints.is_none()) {
    return arm->CameraPose(JointsWithinLimits(joints, *arm));
  } else if (!scene.start_joints_rad.empty()) {
    q = Eigen::Map<const Eigen::VectorXd>(scene.start_joints_rad.data(),
                                          static_cast<Eigen::Index>(scene.start_joints_rad.size()));
  } else {
    throw py::value_error(
        fmt::format("scene '{}' has no start joints: give joints or camera_pose", scene.name));
  }
  ThrowIfError(arm->CheckJoints(q));
  return arm->CameraPose(q);
}

py::dict Render(PyScene& s, const py::object& camera_pose, const py::object& joints,
                const std::optional<CameraIntrinsics>& camera, bool noise, const py::object& arm) {
  const RigidTransform X_WC = RenderPose(s.scene, camera_pose, joints, arm);
  const CameraIntrinsics K = camera.value_or(CameraIntrinsics::RealSenseD435());
  ThrowIfError(K.Validate());
  double render_ms = 0.0;
  sim::RenderedFrame frame = [&] {
    py::gil_scoped_release release;
    const auto t0 = std::chrono::steady_clock::now();
    sim::RenderedFrame f = s.Renderer().Render(K, X_WC);
    render_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (noise) {
      // As `avp render`: the D435-like noise, seeded from the scene's seed.
      sim::DepthNoiseConfig config;
      config.enabled = true;
      Rng rng = Rng(s.scene.seed).Fork("render-noise");
      sim::ApplyDepthNoise(config, f, rng);
    }
    return f;
  }();
  py::dict d;
  d["rgb"] = ImageArray(std::move(frame.rgbd.rgb));
  d["depth"] = ImageArray(std::move(frame.rgbd.depth_m));
  d["instance"] = ImageArray(std::move(frame.instance_ids));
  d["class"] = ImageArray(std::move(frame.class_ids));
  d["camera_pose"] = TransformToArray(X_WC);
  d["render_ms"] = render_ms;
  return d;
}

void BindCamera(py::module_& m) {
  py::class_<CameraIntrinsics>(m, "Camera",
                               "A pinhole camera: image size, focal lengths and principal point "
                               "(pixels), depth range (metres).")
      .def(py::init([](int width, int height, double fx, double fy, double cx, double cy,
                       double min_depth_m, double max_depth_m) {
             CameraIntrinsics K{width, height, fx, fy, cx, cy, min_depth_m, max_depth_m};
             ThrowIfError(K.Validate());
             return K;
           }),
           py::arg("width"), py::arg("height"), py::arg("fx"), py::arg("fy"), py::arg("cx"),
           py::arg("cy"), py::arg("min_depth_m") = 0.1, py::arg("max_depth_m") = 3.0)
      .def_static("d435", &CameraIntrinsics::RealSenseD435,
                  "The RealSense D435's colour camera at 640x480 (avp's default).")
      .def_readonly("width", &CameraIntrinsics::width)
      .def_readonly("height", &CameraIntrinsics::height)
      .def_readonly("fx", &CameraIntrinsics::fx)
      .def_readonly("fy", &CameraIntrinsics::fy)
      .def_readonly("cx", &CameraIntrinsics::cx)
      .def_readonly("cy", &CameraIntrinsics::cy)
      .def_readonly("min_depth_m", &CameraIntrinsics::min_depth_m)
      .def_readonly("max_depth_m", &CameraIntrinsics::max_depth_m)
      .def("__repr__", [](const CameraIntrinsics& K) {
        return fmt::format("<avp.Camera {}x{} fx {} fy {} cx {} cy {} depth [{}, {}] m>", K.width,
                           K.height, K.fx, K.fy, K.cx, K.cy, K.min_depth_m, K.max_depth_m);
      });
}

void BindArm(py::module_& m) {
  py::class_<robot::ArmModel, std::shared_ptr<robot::ArmModel>>(
      m, "Arm",
      "An arm's kinematics (URDF + arm config; the igus ReBeL with a D435 by default). Joints "
      "are radians in URDF order; poses 4x4 float64 arrays in the base frame.")
      .def_static("load", &LoadArmModel, py::arg("path") = py::none(),
                  "An arm configuration YAML (configs/arms/), or the default arm.")
      .def_property_readonly("joint_names", &robot::ArmModel::joint_names)
      .def_property_readonly("lower_limits",
                             [](const robot::ArmModel& a) { return VectorArray(a.lower_limits()); })
      .def_property_readonly("upper_limits",
                             [](const robot::ArmModel& a) { return VectorArray(a.upper_limits()); })
      .def_property_readonly("home",
                             [](const robot::ArmModel& a) { return VectorArray(a.home_joints()); })
      .def(
          "flange_pose",
          [](const robot::ArmModel& a, const py::object& q) {
            return TransformToArray(a.ForwardKinematics(JointsWithinLimits(q, a)));
          },
          py::arg("joints"), "Forward kinematics: the flange's pose.")
      .def(
          "camera_pose",
          [](const robot::ArmModel& a, const py::object& q) {
            return TransformToArray(a.CameraPose(JointsWithinLimits(q, a)));
          },
          py::arg("joints"), "The camera optical frame's pose at these joints.")
      .def(
          "camera_ik",
          [](const robot::ArmModel& a, const py::object& pose, const py::object& seed_joints,
             uint64_t seed) -> py::object {
            const RigidTransform X_WC = TransformFromArray(pose, "camera_pose");
            const Eigen::VectorXd q0 =
                seed_joints.is_none() ? a.home_joints() : JointsFrom(seed_joints, a);
            Rng rng(seed);
            robot::IkResult r;
            {
              py::gil_scoped_release release;
              r = a.SolveCameraIk(X_WC, q0, rng);
            }
            if (!r.ok()) return py::none();
            return VectorArray(r.q);
          },
          py::arg("camera_pose"), py::arg("seed_joints") = py::none(), py::arg("seed") = 0,
          "Joints within the limits that put the camera at camera_pose, or None when none is "
          "found (random restarts seeded by `seed`).")
      .def(
          "is_reachable",
          [](const robot::ArmModel& a, const py::object& pose) {
            return a.IsReachable(TransformFromArray(pose, "camera_pose"));
          },
          py::arg("camera_pose"), "Whether IK reaches this camera pose.");
}

/// An image argument copied into avp's image type: `what` names it in errors (CheckedArray).
template <typename Image>
Image ImageFrom(const py::handle& value, std::string_view what, const py::dtype& dtype,
                std::vector<py::ssize_t> shape) {
  const py::array a = CheckedArray(value, what, dtype, shape);
  // The image limits every reader of images keeps (io/image_limits.h), before anything is copied.
  ThrowIfError(io::CheckImageSize(static_cast<uint64_t>(a.shape(1)),
                                  static_cast<uint64_t>(a.shape(0)), what));
  Image image(static_cast<int>(a.shape(1)), static_cast<int>(a.shape(0)));
  const auto* d = static_cast<const typename Image::value_type*>(a.data());
  std::copy(d, d + image.data().size(), image.data().begin());
  return image;
}

/// The frame and labels avp.segment segments: an (h, w, 3) uint8 RGB array alone (`avp segment`'s
/// nominal 60-degree camera, zero depth), or a render's dict with its depth, pose and labels
/// (the D435 when the size is its own). `has_labels` says whether labels were given.
RgbdFrame FrameFrom(const py::object& image, SimulatorLabels& labels, bool& has_labels) {
  RgbdFrame frame;
  has_labels = false;
  const bool render = py::isinstance<py::dict>(image);
  if (!render) {
    frame.rgb = ImageFrom<ImageRgb8>(image, "image", py::dtype::of<uint8_t>(), {-1, -1, 3});
  } else {
    const auto d = image.cast<py::dict>();
    if (!d.contains("rgb")) throw py::value_error("image: a dict must hold 'rgb' (a render's)");
    frame.rgb =
        ImageFrom<ImageRgb8>(d["rgb"], "image['rgb']", py::dtype::of<uint8_t>(), {-1, -1, 3});
    const int w = frame.rgb.width(), h = frame.rgb.height();
    if (d.contains("depth")) {
      frame.depth_m =
          ImageFrom<DepthImage>(d["depth"], "image['depth']", py::dtype::of<float>(), {h, w});
    }
    if (d.contains("camera_pose")) {
      frame.X_WC = TransformFromArray(d["camera_pose"], "image['camera_pose']");
    }
    if (d.contains("instance") && d.contains("class")) {
      labels.instance_ids = ImageFrom<InstanceImage>(d["instance"], "image['instance']",
                                                     py::dtype::of<uint16_t>(), {h, w});
      labels.class_ids =
          ImageFrom<ClassImage>(d["class"], "image['class']", py::dtype::of<uint8_t>(), {h, w});
      has_labels = true;
    }
  }
  const int w = frame.rgb.width(), h = frame.rgb.height();
  if (frame.depth_m.empty()) frame.depth_m = DepthImage(w, h, 0.0f);
  const CameraIntrinsics d435 = CameraIntrinsics::RealSenseD435();
  frame.K = render && d435.width == w && d435.height == h
                ? d435
                : CameraIntrinsics::FromHorizontalFov(w, h, 60.0);
  return frame;
}

/// A segmentation as avp.segment returns it: masks (n, h, w) bool and per instance its class,
/// phrase, scores and box.
py::dict SegmentationDict(const segmentation::SegmentResult& r) {
  const std::vector<InstanceMask>& instances = r.segmentation.instances;
  const size_t n = instances.size();
  py::array_t<bool> masks(std::vector<py::ssize_t>{static_cast<py::ssize_t>(n), r.height, r.width});
  bool* out = masks.mutable_data();
  std::vector<uint8_t> classes;
  std::vector<float> scores, mask_scores;
  std::vector<double> boxes;
  py::list names, phrases;
  const double nan = std::nan("");
  for (size_t i = 0; i < n; ++i) {
    const InstanceMask& im = instances[i];
    const auto px = im.mask.data();
    for (size_t k = 0; k < px.size(); ++k) out[i * px.size() + k] = px[k] != 0;
    classes.push_back(static_cast<uint8_t>(im.semantic_class));
    names.append(std::string(ToString(im.semantic_class)));
    phrases.append(im.label);
    scores.push_back(im.confidence);
    mask_scores.push_back(im.mask_score);
    boxes.insert(boxes.end(), {im.box ? im.box->x0 : nan, im.box ? im.box->y0 : nan,
                               im.box ? im.box->x1 : nan, im.box ? im.box->y1 : nan});
  }
  py::dict d;
  d["masks"] = masks;
  d["classes"] = OwnedArray(std::move(classes));
  d["class_names"] = names;
  d["labels"] = phrases;
  d["scores"] = OwnedArray(std::move(scores));
  d["mask_scores"] = OwnedArray(std::move(mask_scores));
  d["boxes"] = OwnedMatrix(std::move(boxes), 4);
  d["backend"] = r.backend;
  d["total_ms"] = r.total_ms;
  return d;
}

/// avp.segment: one image through a registered segmenter (segmentation::SegmentWith, as
/// `avp segment`).
py::dict Segment(const py::object& image, const std::string& prompt, const std::string& backend,
                 const std::shared_ptr<PyScene>& scene, float threshold, uint64_t seed,
                 uint64_t frame_index, const std::map<std::string, std::string>& options) {
  SimulatorLabels labels;
  bool has_labels = false;
  const RgbdFrame frame = FrameFrom(image, labels, has_labels);
  if (scene != nullptr) {
    for (const sim::FruitTruth& f : scene->scene.Fruits()) {
      labels.fruits.push_back({f.instance_id, f.center_W, f.mean_radius_m()});
    }
  }
  segmentation::SegmentationRequest request;
  request.frame = &frame;
  request.prompt = prompt;
  request.score_threshold = threshold;
  request.labels = has_labels ? &labels : nullptr;
  request.frame_index = frame_index;
  const OptionValues values(options.begin(), options.end());
  Result<segmentation::SegmentResult> result = [&] {
    py::gil_scoped_release release;
    return segmentation::SegmentWith(ProgramRegistries().segmenters, backend, values, seed,
                                     request);
  }();
  return SegmentationDict(Unwrap(std::move(result)));
}

}  // namespace

void BindSimulation(py::module_& m) {
  m.def("segment", &Segment, py::arg("image"), py::arg("prompt") = "tomato",
        py::arg("backend") = "color", py::arg("scene") = nullptr, py::arg("threshold") = 0.0f,
        py::arg("seed") = 0, py::arg("frame_index") = 0,
        py::arg("options") = std::map<std::string, std::string>{},
        "One image through a registered segmenter (`avp run --segmenter help` lists them: "
        "oracle, color, ywes / lsam with models, remote://host:port): masks (n, h, w) bool, "
        "classes, class_names, labels (the phrases), scores, mask_scores (-1: none), boxes "
        "(n, 4: x0, y0, x1, y1; NaN: none). image: an (h, w, 3) uint8 RGB array, or a render's "
        "dict (its depth, labels and pose go along: the oracle needs them and `scene`).");
  BindCamera(m);
  BindArm(m);
  m.def(
      "scenarios",
      [] {
        py::list out;
        for (const sim::ScenarioEntry& e : ProgramRegistries().scenarios.entries()) {
          py::dict d;
          d["name"] = e.name;
          d["description"] = e.description;
          d["training_only"] = e.training_only;
          out.append(d);
        }
        return out;
      },
      "The built-in scenarios: name, description and training_only (the learned gain's "
      "training family, never an evaluation scene), as `avp scenes` lists them.");
  m.attr("DEFAULT_SCENARIO") = std::string(sim::DefaultScenarioName());
  py::class_<PyScene, std::shared_ptr<PyScene>>(
      m, "Scene",
      "A built-in scenario or a scene file, seeded (the same seed, the same scene on any "
      "machine).")
      .def(py::init(&MakeScene), py::arg("scenario") = "", py::arg("scene_file") = py::none(),
           py::arg("seed") = 0, py::arg("arrangement") = "",
           "scenario: a built-in name (avp.scenarios()); scene_file: a YAML scene "
           "(docs/scene-format.md); neither: the default scenario. arrangement: how a scene "
           "file's plant is placed ('full-occlusion', ...).")
      .def_property_readonly("name", [](const PyScene& s) { return s.scene.name; })
      .def_property_readonly("description", [](const PyScene& s) { return s.scene.description; })
      .def_property_readonly("seed", [](const PyScene& s) { return s.scene.seed; })
      .def_property_readonly("warnings", [](const PyScene& s) { return s.scene.warnings; })
      .def_property_readonly("num_triangles",
                             [](const PyScene& s) { return s.scene.num_triangles(); })
      .def_property_readonly(
          "plant_bounds", [](const PyScene& s) { return BoxArray(s.scene.plant_bounds); },
          "[[min x, y, z], [max x, y, z]] of the plant (metres).")
      .def_property_readonly(
          "start_joints",
          [](const PyScene& s) {
            return OwnedArray(std::vector<double>(s.scene.start_joints_rad));
          },
          "The arm's start joints (radians; empty: the arm's home).")
      .def(
          "fruits", [](const PyScene& s) { return Fruits(s.scene); },
          "The true fruit: instance id, centre x, y, z and radii (metres), as columns.")
      .def("render", &Render, py::arg("camera_pose") = py::none(), py::arg("joints") = py::none(),
           py::arg("camera") = py::none(), py::arg("noise") = true, py::arg("arm") = py::none(),
           "An RGB-D frame with the simulator's labels, as `avp render` makes it: rgb (h, w, 3) "
           "uint8, depth (h, w) float32 metres (0: no return), instance (h, w) uint16, class "
           "(h, w) uint8, camera_pose (4x4), render_ms (the ray casting alone). The pose: "
           "camera_pose, or the camera of `joints` "
           "(radians) on `arm` (default: the ReBeL), or the scene's start joints. noise: the "
           "D435-like depth noise, seeded from the scene's seed.")
      .def("__repr__", [](const PyScene& s) {
        return fmt::format("<avp.Scene {} seed {}: {} objects, {} fruits>", s.scene.name,
                           s.scene.seed, s.scene.objects.size(), s.scene.Fruits().size());
      });
}

}  // namespace avp::python
