// Planners written in Python (docs/python.md, "Planners in Python"): avp.ViewPlanner subclasses
// registered by name beside the built-in planners, through a C++ ViewPlanner that calls them.
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <pybind11/stl.h>

#include <avp/core/semantic_class.h>
#include <avp/experiment/planner_contract.h>
#include <avp/experiment/registries.h>
#include <avp/planning/planner_registry.h>
#include <avp/planning/view_planner.h>
#include <avp/robot/arm_model.h>

#include "bindings.h"

namespace avp::python {

namespace {

using planning::PlanningRequest;
using planning::PlanResult;
using planning::ViewCandidate;

/// What a Python planner sees of the loop's request, for the length of one plan() call: its
/// fields as arrays, the map (borrowed), the built-in planners run on the very same request and
/// random stream, IK. Every use after the call raises RuntimeError.
class RequestView {
 public:
  RequestView(const PlanningRequest& request, Rng& rng)
      : request_(&request), rng_(&rng), alive_(std::make_shared<bool>(true)) {}

  void Close() { *alive_ = false; }

  const PlanningRequest& request() const {
    if (!*alive_) {
      throw std::runtime_error(
          "this planning request was handed to a planner for one plan() call, which is over");
    }
    return *request_;
  }
  Rng& rng() const {
    (void)request();
    return *rng_;
  }
  std::shared_ptr<PyMap> Map() {
    if (map_ == nullptr) map_ = std::make_shared<PyMap>(*request().map, alive_);
    return map_;
  }

 private:
  const PlanningRequest* request_;
  Rng* rng_;
  std::shared_ptr<bool> alive_;
  std::shared_ptr<PyMap> map_;
};

py::array_t<double> Joints(const Eigen::VectorXd& q) {
  return OwnedArray(std::vector<double>(q.data(), q.data() + q.size()));
}

/// The Python factories by planner name (register_planner may replace one, e.g. a notebook cell
/// run again). Touched only with the GIL held.
std::map<std::string, py::object>& PythonFactories() {
  static auto* factories = new std::map<std::string, py::object>();
  return *factories;
}

/// A candidate a Python planner returned: an avp.Candidate, or a 4x4 camera pose (IK finds its
/// joints, seeded from the current joints). InvalidArgument naming `index` and the problem.
Result<ViewCandidate> CandidateFrom(const py::handle& item, size_t index,
                                    const PlanningRequest& request, Rng& rng) {
  if (py::isinstance<ViewCandidate>(item)) {
    ViewCandidate c = item.cast<ViewCandidate>();
    if (c.q.size() == 0) {
      const robot::IkResult ik = request.arm->SolveCameraIk(c.X_WC, request.q_current, rng);
      c.q = ik.q;
      c.reachable = ik.ok();
    }
    return c;
  }
  if (!py::isinstance<py::array>(item)) {
    return InvalidArgumentError(
        fmt::format("candidate {}: expected an avp.Candidate or a 4x4 float64 camera pose, got {}",
                    index, std::string(py::str(item.get_type().attr("__name__")))));
  }
  ViewCandidate c;
  try {
    c.X_WC = TransformFromArray(item, fmt::format("candidate {}", index));
  } catch (const std::exception& e) {
    return InvalidArgumentError(e.what());
  }
  const robot::IkResult ik = request.arm->SolveCameraIk(c.X_WC, request.q_current, rng);
  c.q = ik.q;
  c.reachable = ik.ok();
  c.source = "python";
  return c;
}

/// A candidate the loop may take: joints of the arm's size within its limits that put the
/// camera where the candidate says (2 mm, 0.05 rad). InvalidArgument naming what is wrong.
Status CheckCandidate(const ViewCandidate& c, size_t index, const robot::ArmModel& arm) {
  if (c.q.size() != arm.num_joints()) {
    return InvalidArgumentError(fmt::format("candidate {}: {} joints, the arm has {}", index,
                                            c.q.size(), arm.num_joints()));
  }
  if (!arm.WithinLimits(c.q)) {
    return InvalidArgumentError(
        fmt::format("candidate {}: joints outside the arm's limits", index));
  }
  const RigidTransform X = arm.CameraPose(c.q);
  if (!X.IsNearlyEqualTo(c.X_WC, 2e-3, 0.05)) {
    return InvalidArgumentError(
        fmt::format("candidate {}: its joints put the camera at {}, not at its pose {}", index,
                    X.ToString(), c.X_WC.ToString()));
  }
  return Status::Ok();
}

/// What a Python planner returned, as the loop's answer: an avp.Plan (its ranking and stopping
/// rule kept), or a sequence of candidates best first. Candidates IK does not reach, that
/// collide (with a collision checker) or that repeat a fused view are dropped and counted.
Result<PlanResult> ToPlanResult(const py::object& out, const PlanningRequest& request, Rng& rng,
                                std::string_view name) {
  PlanResult plan;
  std::vector<ViewCandidate> candidates;
  if (py::isinstance<PlanResult>(out)) {
    plan = out.cast<PlanResult>();
    candidates = std::move(plan.ranked);
    plan.ranked.clear();
  } else if (out.is_none()) {
  } else if (py::isinstance<py::sequence>(out) && !py::isinstance<py::str>(out) &&
             !py::isinstance<py::array>(out)) {
    const auto items = py::reinterpret_borrow<py::sequence>(out);
    for (size_t i = 0; i < items.size(); ++i) {
      AVP_ASSIGN_OR_RETURN(ViewCandidate c, CandidateFrom(items[i], i, request, rng));
      candidates.push_back(std::move(c));
    }
    plan.generated = candidates.size();
  } else {
    return InvalidArgumentError(fmt::format(
        "plan() returned {}: expected an avp.Plan, a list of avp.Candidate or of 4x4 poses, or "
        "None",
        std::string(py::str(out.get_type().attr("__name__")))));
  }
  for (size_t i = 0; i < candidates.size(); ++i) {
    ViewCandidate& c = candidates[i];
    if (!c.reachable) continue;
    AVP_RETURN_IF_ERROR(CheckCandidate(c, i, *request.arm));
    if (planning::IsNearAny(c.X_WC, request.fused_views)) c.reachable = false;
  }
  const size_t colliding = planning::DropCollidingCandidates(request, candidates);
  for (ViewCandidate& c : candidates) {
    if (c.reachable) plan.ranked.push_back(std::move(c));
  }
  if (plan.generated == 0) plan.generated = candidates.size();
  plan.reachable = std::max(plan.reachable, plan.ranked.size());
  plan.in_collision = std::max(plan.in_collision, colliding);
  if (plan.status.ok() && plan.ranked.empty()) {
    plan.status = NotFoundError(fmt::format(
        "no valid candidate: planner '{}' returned {}, none reachable, free and not yet fused",
        name, plan.generated));
  }
  return plan;
}

/// Python's traceback of the exception being handled, as text.
std::string FormatTraceback(py::error_already_set& e) {
  try {
    py::object format = py::module_::import("traceback").attr("format_exception");
    std::string text;
    for (const py::handle& line : format(e.type(), e.value(), e.trace())) {
      text += line.cast<std::string>();
    }
    return text;
  } catch (...) {
    return e.what();
  }
}

/// A planner written in Python: an avp.ViewPlanner instance whose plan(request) is called with the
/// GIL held. An exception it raises, an answer that is not one, or a call longer than
/// `timeout_s` throws (the loop ends the episode as a planner fault, the traceback in its
/// reason).
class PythonPlanner : public planning::ViewPlanner {
 public:
  PythonPlanner(std::string name, py::object instance, double timeout_s)
      : name_(std::move(name)), instance_(std::move(instance)), timeout_s_(timeout_s) {}
  ~PythonPlanner() override {
    py::gil_scoped_acquire gil;
    instance_ = py::object();
  }

  std::string_view name() const override { return name_; }

  PlanResult Plan(const PlanningRequest& request, Rng& rng) override {
    if (Status s = planning::ValidateRequest(request); !s.ok()) {
      PlanResult refused;
      refused.status = s;
      return refused;
    }
    py::gil_scoped_acquire gil;
    auto view = std::make_shared<RequestView>(request, rng);
    const auto t0 = std::chrono::steady_clock::now();
    py::object out;
    try {
      out = instance_.attr("plan")(view);
    } catch (py::error_already_set& e) {
      view->Close();
      throw std::runtime_error(
          fmt::format("the Python planner raised an exception:\n{}", FormatTraceback(e)));
    }
    view->Close();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (seconds > timeout_s_) {
      throw std::runtime_error(fmt::format(
          "plan() took {:.2f} s, over its {:g} s (register_planner(..., timeout_s=...))", seconds,
          timeout_s_));
    }
    Result<PlanResult> plan = ToPlanResult(out, request, rng, name_);
    if (!plan.ok()) {
      throw std::runtime_error(fmt::format("plan() answered wrongly: {}", plan.status().message()));
    }
    return std::move(*plan);
  }

 private:
  std::string name_;
  py::object instance_;
  double timeout_s_;
};

void RegisterPythonPlanner(const std::string& name, py::object factory,
                           const std::string& description, double timeout_s) {
  if (name.empty()) throw py::value_error("a planner's name must not be empty");
  if (!std::isfinite(timeout_s) || timeout_s <= 0.0) {
    throw py::value_error(fmt::format("timeout_s ({}) must be > 0", timeout_s));
  }
  auto& factories = PythonFactories();
  planning::PlannerRegistry& planners = MutableProgramRegistries().planners;
  if (factories.contains(name)) {  // a Python planner again: the new factory replaces the old
    factories[name] = std::move(factory);
    return;
  }
  if (planners.Find(name) != nullptr) {
    throw py::value_error(fmt::format(
        "planner '{}' is already registered (a built-in planner): choose another name", name));
  }
  factories[name] = std::move(factory);
  planning::PlannerEntry entry;
  entry.name = name;
  entry.description = description.empty() ? "a planner written in Python" : description;
  entry.make = [name, timeout_s](const AnyOptions&, const planning::PlannerContext&)
      -> Result<std::unique_ptr<planning::ViewPlanner>> {
    py::gil_scoped_acquire gil;
    try {
      py::object instance = PythonFactories().at(name)();
      if (!py::hasattr(instance, "plan")) {
        return InvalidArgumentError(
            fmt::format("planner '{}': its factory made an object without a plan() method", name));
      }
      return std::unique_ptr<planning::ViewPlanner>(
          std::make_unique<PythonPlanner>(name, std::move(instance), timeout_s));
    } catch (py::error_already_set& e) {
      return InvalidArgumentError(
          fmt::format("planner '{}': its factory raised:\n{}", name, FormatTraceback(e)));
    }
  };
  ThrowIfError(planners.Add(std::move(entry)));
}

/// A built-in (or registered) planner with its defaults and `options`, run on the request.
PlanResult PlanWith(const RequestView& view, const std::string& name, const py::dict& options) {
  const PlanningRequest& request = view.request();
  const experiment::Registries& registries = ProgramRegistries();
  const planning::PlannerEntry* entry = registries.planners.Find(name);
  if (entry == nullptr) {
    throw py::value_error(fmt::format("unknown planner '{}' (avp.planners() lists them)", name));
  }
  if (PythonFactories().contains(name)) {
    throw py::value_error(fmt::format("plan_with('{}'): a Python planner; call it directly", name));
  }
  if (entry->needs_ground_truth) {
    throw py::value_error(fmt::format(
        "plan_with('{}'): it needs the ground truth, which a planner is not handed", name));
  }
  AnyOptions values = entry->options;
  for (const auto& [key, value] : options) {
    ThrowIfError(values.Set(py::str(key).cast<std::string>(), py::str(value).cast<std::string>(),
                            fmt::format("planner '{}'", name)));
  }
  ThrowIfError(values.Validate());
  std::unique_ptr<planning::ViewPlanner> planner =
      Unwrap(registries.planners.Make(name, values, planning::PlannerContext{}));
  Rng& rng = view.rng();
  py::gil_scoped_release release;
  return planner->Plan(request, rng);
}

py::array_t<double> Poses(const std::vector<RigidTransform>& poses) {
  std::vector<double> values;
  values.reserve(poses.size() * 16);
  for (const RigidTransform& X : poses) {
    const Eigen::Matrix4d M = X.ToMatrix4();
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) values.push_back(M(r, c));
    }
  }
  auto* owned = new std::vector<double>(std::move(values));
  py::capsule base(owned, [](void* p) { delete static_cast<std::vector<double>*>(p); });
  using Shape = std::vector<py::ssize_t>;
  constexpr auto kDouble = static_cast<py::ssize_t>(sizeof(double));
  return py::array_t<double>(Shape{static_cast<py::ssize_t>(poses.size()), 4, 4},
                             Shape{16 * kDouble, 4 * kDouble, kDouble}, owned->data(), base);
}

void BindCandidate(py::module_& m) {
  py::class_<ViewCandidate>(m, "Candidate",
                            "A candidate camera view: its pose, the joints that reach it, its "
                            "gain, cost and utility (a built-in planner's, or your own).")
      .def(py::init([](const py::object& pose, const py::object& joints, double gain, double cost,
                       double utility, const std::string& source) {
             ViewCandidate c;
             c.X_WC = TransformFromArray(pose, "pose");
             if (!joints.is_none()) {
               const py::array a = CheckedArray(joints, "joints", py::dtype::of<double>(), {-1});
               const auto* d = static_cast<const double*>(a.data());
               c.q = Eigen::Map<const Eigen::VectorXd>(d, a.shape(0));
               c.reachable = true;
             }
             c.gain = gain;
             c.cost = cost;
             c.utility = utility;
             c.source = source;
             return c;
           }),
           py::arg("pose"), py::arg("joints") = py::none(), py::arg("gain") = 0.0,
           py::arg("cost") = 0.0, py::arg("utility") = 0.0, py::arg("source") = "python",
           "pose: the camera optical frame (4x4 float64, base frame). joints: radians that reach "
           "it (checked), or None: IK finds them when the planner returns it.")
      .def_property_readonly("pose",
                             [](const ViewCandidate& c) { return TransformToArray(c.X_WC); })
      .def_property_readonly("joints", [](const ViewCandidate& c) { return Joints(c.q); })
      .def_readonly("reachable", &ViewCandidate::reachable)
      .def_readonly("in_collision", &ViewCandidate::in_collision)
      .def_readwrite("gain", &ViewCandidate::gain)
      .def_readwrite("cost", &ViewCandidate::cost)
      .def_readwrite("utility", &ViewCandidate::utility)
      .def_readwrite("source", &ViewCandidate::source)
      .def_property_readonly("gain_terms",
                             [](const ViewCandidate& c) {
                               py::dict d;
                               for (const auto& [k, v] : c.gain_terms) d[py::str(k)] = v;
                               return d;
                             })
      .def("__repr__", [](const ViewCandidate& c) {
        return fmt::format("<avp.Candidate {} gain {:.4g} cost {:.3g} utility {:.4g} ({})>",
                           c.X_WC.ToString(), c.gain, c.cost, c.utility, c.source);
      });
}

void BindPlan(py::module_& m) {
  py::class_<PlanResult>(m, "Plan",
                         "A planner's answer: the candidates best first, how many were made and "
                         "reachable, and its stopping rule.")
      .def(py::init([](const std::vector<ViewCandidate>& ranked, bool stop,
                       const std::string& stop_reason) {
             PlanResult p;
             p.ranked = ranked;
             p.generated = ranked.size();
             p.stop = stop;
             p.stop_reason = stop_reason;
             return p;
           }),
           py::arg("ranked"), py::arg("stop") = false, py::arg("stop_reason") = "")
      .def_readwrite("ranked", &PlanResult::ranked)
      .def_readonly("generated", &PlanResult::generated)
      .def_readonly("reachable", &PlanResult::reachable)
      .def_readonly("in_collision", &PlanResult::in_collision)
      .def_readwrite("stop", &PlanResult::stop)
      .def_readwrite("stop_reason", &PlanResult::stop_reason)
      .def_property_readonly("status",
                             [](const PlanResult& p) {
                               return p.status.ok() ? py::object(py::none())
                                                    : py::object(py::str(p.status.ToString()));
                             })
      .def("__repr__", [](const PlanResult& p) {
        return fmt::format("<avp.Plan {} ranked of {} generated{}>", p.ranked.size(), p.generated,
                           p.stop ? ", stop" : "");
      });
}

void BindRequest(py::module_& m) {
  py::class_<RequestView, std::shared_ptr<RequestView>>(
      m, "PlanningRequest",
      "What a planner is handed for one plan() call (valid only during it): the map, the arm, "
      "the current and start views, the views fused so far, the region of interest, the budget.")
      .def_property_readonly("map", &RequestView::Map,
                             "The map so far (an avp.Map, borrowed for the call).")
      .def_property_readonly(
          "arm",
          [](const RequestView& v) { return std::make_shared<robot::ArmModel>(*v.request().arm); })
      .def_property_readonly("joints",
                             [](const RequestView& v) { return Joints(v.request().q_current); })
      .def_property_readonly(
          "camera_pose",
          [](const RequestView& v) { return TransformToArray(v.request().X_WC_current); })
      .def_property_readonly("start_joints",
                             [](const RequestView& v) { return Joints(v.request().q_start); })
      .def_property_readonly(
          "start_pose",
          [](const RequestView& v) { return TransformToArray(v.request().X_WC_start); })
      .def_property_readonly(
          "fused_views", [](const RequestView& v) { return Poses(v.request().fused_views); },
          "The camera poses fused so far, (n, 4, 4).")
      .def_property_readonly("camera", [](const RequestView& v) { return v.request().K; })
      .def_property_readonly(
          "roi", [](const RequestView& v) { return BoxArray(v.request().roi); },
          "The region of interest, [[min x, y, z], [max x, y, z]] (metres).")
      .def_property_readonly(
          "view_index", [](const RequestView& v) { return v.request().view_index; },
          "The view to choose (1: the second fused view).")
      .def_property_readonly("views_total",
                             [](const RequestView& v) { return v.request().views_total; })
      .def_property_readonly(
          "target_class",
          [](const RequestView& v) { return std::string(ToString(v.request().target_class)); })
      .def_property_readonly(
          "prompt", [](const RequestView& v) { return v.request().prompt; },
          "The episode's text prompt ('tomato').")
      .def("plan_with", &PlanWith, py::arg("planner"), py::arg("options") = py::dict(),
           "A built-in planner (its registered defaults, `options` over them) run on this very "
           "request and random stream: its avp.Plan. Returned as it is, it makes the episode the "
           "built-in planner's own.")
      .def(
          "candidate",
          [](const RequestView& v, const py::object& pose) {
            ViewCandidate c = Unwrap(CandidateFrom(pose, 0, v.request(), v.rng()));
            return c;
          },
          py::arg("pose"),
          "An avp.Candidate for a camera pose: IK from the current joints (reachable says "
          "whether it found joints).");
}

/// The contract's checks (experiment::PlannerContractViolations) on a registered planner.
std::vector<std::string> CheckPlanner(const std::string& name) {
  const planning::PlannerEntry* entry = ProgramRegistries().planners.Find(name);
  if (entry == nullptr) {
    throw py::value_error(fmt::format("unknown planner '{}' (avp.planners() lists them)", name));
  }
  if (entry->needs_ground_truth) {
    throw py::value_error(fmt::format(
        "planner '{}' needs the ground truth: its contract is checked by the C++ suite", name));
  }
  std::unique_ptr<planning::ViewPlanner> planner =
      Unwrap(ProgramRegistries().planners.Make(name, entry->options, planning::PlannerContext{}));
  // Built once; its error raised with the GIL held (ThrowIfError may set a Python error).
  static const experiment::ContractWorld* world = [] {
    Result<std::unique_ptr<experiment::ContractWorld>> made = [] {
      py::gil_scoped_release release;
      return experiment::MakeContractWorld();
    }();
    return Unwrap(std::move(made)).release();
  }();
  py::gil_scoped_release release;
  return experiment::PlannerContractViolations(*planner, *world);
}

}  // namespace

void BindPlanners(py::module_& m) {
  m.def("check_planner", &CheckPlanner, py::arg("name"),
        "The planner contract every built-in planner keeps (docs/extending.md), checked on a "
        "registered planner: its violations, one sentence each (empty: it keeps it).");
  BindCandidate(m);
  BindPlan(m);
  BindRequest(m);
  m.def("_register_planner", &RegisterPythonPlanner, py::arg("name"), py::arg("factory"),
        py::arg("description"), py::arg("timeout_s"));
}

}  // namespace avp::python
