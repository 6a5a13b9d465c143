#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/entropy.h>
#include <avp/core/error.h>
#include <avp/core/parallel.h>
#include <avp/planning/avp_nbv_planner.h>
#include <avp/planning/view_features.h>

namespace avp::planning {

namespace {

/// Weight of an unknown voxel of the ROI that is not near a target voxel: w_unknown_roi times a
/// Gaussian of its horizontal distance from the plant's core (fruit hangs around the stem), or
/// flat when roi_axis_sigma_m is 0.
double RoiWeight(double d, const AvpNbvOptions& o) {
  if (o.roi_axis_sigma_m <= 0.0) return o.w_unknown_roi;
  return o.w_unknown_roi * std::exp(-0.5 * d * d / (o.roi_axis_sigma_m * o.roi_axis_sigma_m));
}

/// Occlusion probability of an unknown voxel of the ROI: p_unknown near the plant's core, falling
/// as a Gaussian (sigma = unknown_occlusion_sigma_m) of the horizontal distance from it, since the
/// ROI box is mostly air away from the stem (flat when the sigma is 0); per voxel of the map's edge
/// (OcclusionPerVoxel).
double UnknownOcclusion(double d, double voxel_size_m, const AvpNbvOptions& o) {
  const double p =
      o.unknown_occlusion_sigma_m <= 0.0
          ? o.p_unknown
          : o.p_unknown * std::exp(-0.5 * d * d /
                                   (o.unknown_occlusion_sigma_m * o.unknown_occlusion_sigma_m));
  return OcclusionPerVoxel(p, voxel_size_m, o.occlusion_voxel_size_m);
}

/// RoiWeight and UnknownOcclusion of a voxel. Both depend only on the voxel's column (x, y), so
/// the planner tabulates them once per plan over the ROI's columns (two exponentials per unknown
/// voxel of every ray were most of a step's time); without a table, or outside it, they are
/// computed directly. The table holds the very values the direct computation gives.
class CorePrior {
 public:
  /// Direct computation (the per-ray API and the reference evaluator).
  CorePrior(const Box3& roi, double voxel_size_m, const AvpNbvOptions& o)
      : roi_(roi), s_(voxel_size_m), o_(o) {}
  /// With the table over the ROI's columns.
  static CorePrior Tabulated(const Box3& roi, double voxel_size_m, const AvpNbvOptions& o) {
    CorePrior p(roi, voxel_size_m, o);
    if (roi.IsEmpty()) return p;
    const VoxelKey lo = VoxelKey::FromPoint(roi.min(), voxel_size_m);
    const VoxelKey hi = VoxelKey::FromPoint(roi.max(), voxel_size_m);
    p.x0_ = lo.x;
    p.y0_ = lo.y;
    p.nx_ = int64_t{hi.x} - lo.x + 1;
    p.ny_ = int64_t{hi.y} - lo.y + 1;
    if (p.nx_ <= 0 || p.ny_ <= 0 || p.nx_ * p.ny_ > (int64_t{1} << 24)) {
      p.nx_ = p.ny_ = 0;
      return p;
    }
    p.table_.resize(static_cast<size_t>(p.nx_ * p.ny_));
    for (int64_t iy = 0; iy < p.ny_; ++iy) {
      for (int64_t ix = 0; ix < p.nx_; ++ix) {
        const VoxelKey k{static_cast<int32_t>(p.x0_ + ix), static_cast<int32_t>(p.y0_ + iy), lo.z};
        p.table_[static_cast<size_t>(ix + p.nx_ * iy)] = p.Compute(k);
      }
    }
    return p;
  }

  /// {RoiWeight, UnknownOcclusion} of voxel k.
  std::pair<double, double> At(const VoxelKey& k) const { return view().At(k); }

  /// The table's pointer and bounds by value: a ray's walk keeps a copy in registers (through a
  /// reference they would be reloaded after every store of the walk, which may alias them).
  struct View {
    const std::pair<double, double>* table;
    int64_t x0, y0, nx, ny;
    const CorePrior* prior;
    std::pair<double, double> At(const VoxelKey& k) const {
      const int64_t ix = int64_t{k.x} - x0;
      const int64_t iy = int64_t{k.y} - y0;
      if (ix >= 0 && iy >= 0 && ix < nx && iy < ny) return table[ix + nx * iy];
      return prior->Compute(k);
    }
  };
  View view() const { return {table_.data(), x0_, y0_, nx_, ny_, this}; }

 private:
  std::pair<double, double> Compute(const VoxelKey& k) const {
    // Only x and y of the centre matter (PlantCoreDistance is horizontal).
    const double d = PlantCoreDistance(k.Center(s_), roi_);
    return {RoiWeight(d, o_), UnknownOcclusion(d, s_, o_)};
  }

  Box3 roi_;
  double s_;
  const AvpNbvOptions& o_;
  int64_t x0_ = 0, y0_ = 0, nx_ = 0, ny_ = 0;
  std::vector<std::pair<double, double>> table_;
};

/// The options a ray's voxels read, by value (a ray keeps a copy in registers, see
/// CorePrior::View).
struct GainParams {
  GainParams(const AvpNbvOptions& o, double voxel_size_m)
      : w_target_entropy(o.w_target_entropy),
        w_unknown_near_target(o.w_unknown_near_target),
        w_predicted_target(o.w_predicted_target),
        p_unknown_outside_roi(
            OcclusionPerVoxel(o.p_unknown_outside_roi, voxel_size_m, o.occlusion_voxel_size_m)),
        surface_gain(o.surface_gain),
        min_range2(o.min_gain_range_m * o.min_gain_range_m),
        range_ref(o.range_weight_ref_m),
        range_ref2(o.range_weight_ref_m * o.range_weight_ref_m) {}
  double w_target_entropy, w_unknown_near_target, w_predicted_target, p_unknown_outside_roi;
  bool surface_gain;
  double min_range2, range_ref, range_ref2;
};

/// The surface a ray stands for grows with the square of its range (the rays sample the image
/// sparsely, the camera sees every voxel of the pixel block): (|c - eye| / ref)^2, or 1 when
/// range weighting is off; 0 closer than min_gain_range_m.
double RangeWeight(const VoxelKey& k, double voxel_size_m, const Eigen::Vector3d& eye,
                   const GainParams& o) {
  const double d2 = (k.Center(voxel_size_m) - eye).squaredNorm();
  if (d2 < o.min_range2) return 0.0;
  if (o.range_ref <= 0.0) return 1.0;
  return d2 / o.range_ref2;
}

/// Nothing beyond the ROI adds gain (its unknown space is air, and the target lies inside it), so
/// a ray ends where it leaves the ROI, plus one voxel diagonal so that every voxel whose centre
/// lies in the ROI is still visited; false when the segment misses the ROI. Rays leave the plant
/// long before their 1 m: walking the rest through empty space was half of a step's time.
bool ClipRayToRoi(const Eigen::Vector3d& from, const Eigen::Vector3d& to, const Box3& roi,
                  double voxel_size_m, Eigen::Vector3d* clipped) {
  const Eigen::Vector3d d = to - from;
  double t_near = 0.0, t_far = 1.0;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (from[a] < roi.min()[a] || from[a] > roi.max()[a]) return false;
      continue;
    }
    double t1 = (roi.min()[a] - from[a]) / d[a];
    double t2 = (roi.max()[a] - from[a]) / d[a];
    if (t1 > t2) std::swap(t1, t2);
    t_near = std::max(t_near, t1);
    t_far = std::min(t_far, t2);
  }
  if (t_near > t_far) return false;
  const double length = d.norm();
  const double margin = length > 0.0 ? std::sqrt(3.0) * voxel_size_m / length : 0.0;
  *clipped = from + std::min(1.0, t_far + margin) * d;
  return true;
}

/// Where Accumulate also sends each contribution, `sink(part, key, contribution)`: NoSink (the
/// plain gain), TermSink (the gain by part) or KeySink (the voxels a view would reveal, for the
/// lookahead).
struct NoSink {
  void operator()(AvpGainTerm, const VoxelKey&, double) const {}
};
struct TermSink {
  double* terms;
  void operator()(AvpGainTerm t, const VoxelKey&, double c) const { terms[t] += c; }
};
/// A voxel key packed into one integer (21 bits per axis, offset: keys within +-2^20 voxels,
/// +-5 km at 5 mm) with a contribution.
using KeyedContribution = std::pair<uint64_t, double>;
uint64_t PackKey(const VoxelKey& k) {
  const auto axis = [](int32_t v) { return static_cast<uint64_t>(v + (1 << 20)) & 0x1fffffu; };
  return axis(k.x) | axis(k.y) << 21 | axis(k.z) << 42;
}
struct KeySink {
  std::vector<KeyedContribution>* out;
  void operator()(AvpGainTerm, const VoxelKey& k, double c) const {
    out->emplace_back(PackKey(k), c);
  }
};

/// One voxel's contribution; returns false when the ray ends there. Inlined into the walk: a call
/// per voxel, with the GainVoxel materialised for it, was a fifth of a plan step.
template <typename Sink>
[[gnu::always_inline]] inline bool Accumulate(const VoxelKey& k, const GainVoxel& v,
                                              SemanticClass target, double voxel_size_m,
                                              const CorePrior::View& prior,
                                              const Eigen::Vector3d& eye, const GainParams& o,
                                              double& p_vis, double& gain, const Sink& sink) {
  switch (v.state) {
    case mapping::VoxelState::kOccupied:
      if (v.cls == target) {
        const double c = p_vis * o.w_target_entropy * ClampedBinaryEntropyBits(v.p_target) *
                         RangeWeight(k, voxel_size_m, eye, o);
        gain += c;
        sink(kGainTargetEntropy, k, c);
      }
      return false;
    case mapping::VoxelState::kUnknown: {
      double w = 0.0, occlusion = o.p_unknown_outside_roi;
      if (v.in_roi) {
        const auto [roi_w, roi_occ] = prior.At(k);
        w = roi_w;
        occlusion = roi_occ;
      }
      if (v.predicted_target) {
        w = o.w_predicted_target;
      } else {
        if (v.near_target) w = o.w_unknown_near_target;
        if (o.surface_gain) w *= occlusion;
      }
      if (w > 0.0) {
        const double c = p_vis * w * RangeWeight(k, voxel_size_m, eye, o);
        gain += c;
        sink(v.predicted_target ? kGainPredictedTarget
             : v.near_target    ? kGainUnknownNearTarget
                                : kGainUnknownRoi,
             k, c);
      }
      p_vis *= 1.0 - occlusion;
      return p_vis > 1e-4;
    }
    case mapping::VoxelState::kFree:
      return true;
  }
  return true;
}

}  // namespace

const OptionTable<AvpNbvOptions>& AvpNbvOptionTable() {
  static const auto* table = [] {
    using O = AvpNbvOptions;
    auto* t = new OptionTable<O>("avp-nbv option");
    const ValueRange weight = ValueRange::AtLeast(0);
    t->Integer("ray_stride_px", &O::ray_stride_px, "px", ValueRange::Closed(1, 256),
               "a ray through every stride-th pixel (the fine scoring)");
    t->Integer("coarse_ray_stride_px", &O::coarse_ray_stride_px, "px", ValueRange::Closed(0, 256),
               "coarse scoring of every candidate (0: off); at least ray_stride_px");
    t->Integer("refine_top", &O::refine_top, "", ValueRange::AtLeast(1),
               "candidates scored again with the fine rays");
    t->Real("max_range_m", &O::max_range_m, "m", ValueRange::LeftOpen(0, 10), "ray length");
    t->Real("p_unknown", &O::p_unknown, "", ValueRange::HalfOpen(0, 1),
            "occlusion of an unknown ROI voxel at the plant's core, per occlusion voxel");
    t->Real("p_unknown_outside_roi", &O::p_unknown_outside_roi, "", ValueRange::HalfOpen(0, 1),
            "occlusion of an unknown voxel outside the ROI, per occlusion voxel");
    t->Real("occlusion_voxel_size_m", &O::occlusion_voxel_size_m, "m", weight,
            "voxel edge the occlusion probabilities are given for (0: the map's)");
    t->Real("unknown_occlusion_sigma_m", &O::unknown_occlusion_sigma_m, "m", weight,
            "fall-off of the occlusion away from the plant's core (0: flat)");
    t->Real("w_target_entropy", &O::w_target_entropy, "", weight,
            "weight of a target voxel's semantic entropy");
    t->Real("w_predicted_target", &O::w_predicted_target, "", weight,
            "weight of an unknown voxel on a detected fruit's predicted surface");
    t->Real("w_unknown_near_target", &O::w_unknown_near_target, "", weight,
            "weight of an unknown voxel near a target voxel");
    t->Real("w_unknown_roi", &O::w_unknown_roi, "", weight,
            "weight of any other unknown ROI voxel at the plant's core");
    t->Real("roi_axis_sigma_m", &O::roi_axis_sigma_m, "m", weight,
            "fall-off of w_unknown_roi away from the plant's core (0: flat)");
    t->Real("range_weight_ref_m", &O::range_weight_ref_m, "m", weight,
            "range weighting (d / ref)^2 of each contribution (0: off)");
    t->Real("min_gain_range_m", &O::min_gain_range_m, "m", weight,
            "voxels closer than this to the camera add nothing");
    t->Real("w_motion", &O::w_motion, "", weight, "weight of the joint-space motion cost");
    t->Real("w_diversity", &O::w_diversity, "", weight,
            "weight of the distance to the nearest fused view");
    t->Real("diversity_m", &O::diversity_m, "m", weight, "distance at which diversity saturates");
    t->Real("min_gain_bits", &O::min_gain_bits, "bits", weight,
            "stop when the best expected gain is below this (0: never)");
    t->Real("min_gain_fraction", &O::min_gain_fraction, "", ValueRange::HalfOpen(0, 1),
            "stop when the best expected gain is below this fraction of the first plan's (0: "
            "never)");
    t->Flag("record_gain_terms", &O::record_gain_terms,
            "keep each candidate's gain by part (ViewCandidate::gain_terms; for calibration)");
    t->Flag("surface_gain", &O::surface_gain,
            "an unknown voxel counts its weight times the chance the ray ends there");
    t->Text("gain_model", &O::gain_model,
            "a learned gain: a model name under <config dir>/models or an .onnx path (empty: "
            "the hand-written gain)");
    t->Integer("lookahead_views", &O::lookahead_views, "", ValueRange::Closed(0, 2),
               "views looked ahead beyond the next one (0: greedy)");
    t->Integer("lookahead_top", &O::lookahead_top, "", ValueRange::Closed(2, 64),
               "candidates the lookahead considers (the best by utility)");
    t->Real("lookahead_discount", &O::lookahead_discount, "", ValueRange::Closed(0, 1),
            "weight of the views looked ahead against the next one");
    t->Nested("candidates", &O::candidates, ShellCandidateOptionTable());
    t->Nested("grid", &O::grid, GainGridOptionTable());
    t->AddRule([](const O& o, std::vector<std::string>& problems) {
      if (o.coarse_ray_stride_px != 0 && o.coarse_ray_stride_px < o.ray_stride_px) {
        problems.push_back(
            fmt::format("coarse_ray_stride_px ({} px) must be 0 (off) or >= ray_stride_px ({} px)",
                        o.coarse_ray_stride_px, o.ray_stride_px));
      }
    });
    return t;
  }();
  return *table;
}

const char* AvpGainTermName(AvpGainTerm term) {
  switch (term) {
    case kGainTargetEntropy:
      return "target_entropy";
    case kGainPredictedTarget:
      return "predicted_target";
    case kGainUnknownNearTarget:
      return "unknown_near_target";
    case kGainUnknownRoi:
      return "unknown_roi";
    case kGainTermCount:
      break;
  }
  return "?";
}

Status AvpNbvOptions::Validate() const { return AvpNbvOptionTable().Validate(*this); }

PlannerEntry AvpNbvPlannerEntry() {
  return MakePlannerEntry<AvpNbvOptions>(
      "avp-nbv", "avp's occlusion-aware next-best view (docs/planning.md)", AvpNbvOptionTable(),
      AvpNbvOptions{},
      [](AvpNbvOptions o, const PlannerContext&) -> Result<std::unique_ptr<ViewPlanner>> {
        std::shared_ptr<const LearnedGainModel> model;
        if (!o.gain_model.empty()) {
          AVP_ASSIGN_OR_RETURN(model, LearnedGainModel::Load(ResolveGainModelPath(o.gain_model)));
        }
        return std::unique_ptr<ViewPlanner>(std::make_unique<AvpNbvPlanner>(o, std::move(model)));
      });
}

namespace {

template <typename Sink = NoSink>
double RayGain(const GainGrid& grid, const CorePrior& core_prior, const Eigen::Vector3d& eye,
               const Eigen::Vector3d& to_unclipped, const GainParams& params,
               const Sink& sink = {}) {
  double p_vis = 1.0, gain = 0.0;
  const SemanticClass target = grid.target();
  const double s = grid.voxel_size_m();
  // Local copies (registers): see CorePrior::View.
  const CorePrior::View prior = core_prior.view();
  const GainParams options = params;
  const Eigen::Vector3d from = eye;
  Eigen::Vector3d to;
  if (!ClipRayToRoi(from, to_unclipped, grid.roi(), s, &to)) return 0.0;
  // Free voxels add nothing (Accumulate returns true and changes nothing): bricks flagged all-free
  // (GainGridOptions::skip_free_bricks, off by default) are walked through unread.
  grid.WalkSkippingFree(from, to, [&](const VoxelKey& k, const GainVoxel& v) {
    return Accumulate(k, v, target, s, prior, from, options, p_vis, gain, sink);
  });
  return gain;
}

}  // namespace

double OcclusionPerVoxel(double p, double voxel_size_m, double reference_m) {
  if (!(reference_m > 0.0) || voxel_size_m == reference_m) return p;
  return 1.0 - std::pow(1.0 - p, voxel_size_m / reference_m);
}

double AvpRayGain(const GainGrid& grid, const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                  const AvpNbvOptions& options) {
  return RayGain(grid, CorePrior(grid.roi(), grid.voxel_size_m(), options), from, to,
                 GainParams(options, grid.voxel_size_m()));
}

double AvpRayGainReference(const mapping::SemanticMap& map, const Eigen::Vector3d& from,
                           const Eigen::Vector3d& to, SemanticClass target, const Box3& roi,
                           const AvpNbvOptions& options) {
  Eigen::Vector3d to_roi;
  if (!ClipRayToRoi(from, to, roi, map.voxel_size_m(), &to_roi)) return 0.0;
  std::vector<VoxelKey> keys;
  mapping::TraverseRay(from, to_roi, map.voxel_size_m(), [&](const VoxelKey& k) {
    keys.push_back(k);
    return true;
  });
  if (!keys.empty()) keys.pop_back();  // [from, to): the end voxel is not visited
  double p_vis = 1.0, gain = 0.0;
  const CorePrior core_prior(roi, map.voxel_size_m(), options);
  const CorePrior::View prior = core_prior.view();
  const GainParams params(options, map.voxel_size_m());
  const std::vector<TargetSphere> spheres = options.grid.predict_target_surface
                                                ? FitTargetSpheres(map, target)
                                                : std::vector<TargetSphere>{};
  for (const VoxelKey& k : keys) {
    const GainVoxel v =
        ReadGainVoxel(map, k, target, roi, options.grid.near_target_radius_m, &spheres);
    if (!Accumulate(k, v, target, map.voxel_size_m(), prior, from, params, p_vis, gain, NoSink{})) {
      break;
    }
  }
  return gain;
}

double AvpViewGain(const GainGrid& grid, const RigidTransform& X_WC, const CameraIntrinsics& K,
                   const AvpNbvOptions& options) {
  const std::vector<Eigen::Vector3d> dirs = RayDirections(K, options.ray_stride_px);
  const Eigen::Vector3d origin = X_WC.translation();
  const CorePrior prior = CorePrior::Tabulated(grid.roi(), grid.voxel_size_m(), options);
  const GainParams params(options, grid.voxel_size_m());
  double gain = 0.0;
  for (const Eigen::Vector3d& d_C : dirs) {
    gain += RayGain(grid, prior, origin, X_WC * (options.max_range_m * d_C), params);
  }
  return gain;
}

struct AvpGainEvaluator::Impl {
  Impl(const GainGrid& g, const AvpNbvOptions& o)
      : grid(g),
        options(o),
        prior(CorePrior::Tabulated(g.roi(), g.voxel_size_m(), options)),
        params(options, g.voxel_size_m()) {}
  const GainGrid& grid;
  const AvpNbvOptions options;  // before prior, which refers to it
  const CorePrior prior;
  const GainParams params;
};

AvpGainEvaluator::AvpGainEvaluator(const GainGrid& grid, const AvpNbvOptions& options) {
  if (const Status s = options.Validate(); !s.ok()) throw Error(s.ToString());
  impl_ = std::make_unique<Impl>(grid, options);
}
AvpGainEvaluator::~AvpGainEvaluator() = default;
AvpGainEvaluator::AvpGainEvaluator(AvpGainEvaluator&&) noexcept = default;

void AvpGainEvaluator::WalkRay(const Eigen::Vector3d& eye, const Eigen::Vector3d& to,
                               std::array<double, kGainTermCount>& terms,
                               const Visitor& visit) const {
  const GainGrid& grid = impl_->grid;
  const double s = grid.voxel_size_m();
  Eigen::Vector3d end;
  if (!ClipRayToRoi(eye, to, grid.roi(), s, &end)) return;
  const CorePrior::View prior = impl_->prior.view();
  const TermSink sink{terms.data()};
  double p_vis = 1.0, gain = 0.0;
  bool visible = true;
  grid.Walk(eye, end, [&](const VoxelKey& k, const GainVoxel& v) {
    if (visible) {
      visible = Accumulate(k, v, grid.target(), s, prior, eye, impl_->params, p_vis, gain, sink);
    }
    return visit(k, v);
  });
}

namespace {

/// The gain of a candidate over `dirs`, times `scale`; with record_gain_terms its parts too.
double ViewGain(const GainGrid& grid, const CorePrior& prior, const GainParams& params,
                const AvpNbvOptions& options, ViewCandidate& c,
                const std::vector<Eigen::Vector3d>& dirs, double scale) {
  const Eigen::Vector3d origin = c.X_WC.translation();
  double g = 0.0;
  if (!options.record_gain_terms) {
    for (const Eigen::Vector3d& d_C : dirs) {
      g += RayGain(grid, prior, origin, c.X_WC * (options.max_range_m * d_C), params);
    }
    return scale * g;
  }
  std::array<double, kGainTermCount> terms{};
  for (const Eigen::Vector3d& d_C : dirs) {
    g += RayGain(grid, prior, origin, c.X_WC * (options.max_range_m * d_C), params,
                 TermSink{terms.data()});
  }
  c.gain_terms.clear();
  for (int t = 0; t < kGainTermCount; ++t) {
    c.gain_terms.emplace_back(AvpGainTermName(static_cast<AvpGainTerm>(t)), scale * terms[t]);
  }
  return scale * g;
}

/// Viewpoint diversity: the distance to the nearest fused eye, saturating at diversity_m. It does
/// not depend on the gains, so the coarse and the final scoring share it.
std::vector<double> ViewpointDiversity(const std::vector<ViewCandidate>& candidates,
                                       const std::vector<RigidTransform>& fused_views,
                                       double diversity_m) {
  std::vector<double> diversity(candidates.size(), 0.0);
  if (diversity_m <= 0.0) return diversity;
  for (size_t i = 0; i < candidates.size(); ++i) {
    double d_min = std::numeric_limits<double>::infinity();
    for (const RigidTransform& f : fused_views) {
      d_min = std::min(d_min, (f.translation() - candidates[i].X_WC.translation()).norm());
    }
    diversity[i] = std::min(1.0, d_min / diversity_m);
  }
  return diversity;
}

/// The reachable candidates, by index.
std::vector<size_t> Reachable(const std::vector<ViewCandidate>& candidates) {
  std::vector<size_t> reachable;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (candidates[i].reachable) reachable.push_back(i);
  }
  return reachable;
}

/// Utilities from the gains: U = G / max G - w_motion |dq| / max |dq| + w_diversity diversity;
/// returns the largest gain.
double SetUtilities(const AvpNbvOptions& options, const std::vector<size_t>& reachable,
                    const std::vector<double>& diversity, std::vector<ViewCandidate>& candidates) {
  double max_cost = 0.0, max_gain = 0.0;
  for (size_t i : reachable) {
    max_cost = std::max(max_cost, candidates[i].cost);
    max_gain = std::max(max_gain, candidates[i].gain);
  }
  for (size_t i = 0; i < candidates.size(); ++i) {
    ViewCandidate& c = candidates[i];
    const double g = max_gain > 0.0 ? c.gain / max_gain : 0.0;
    const double m = max_cost > 0.0 ? c.cost / max_cost : 0.0;
    c.utility = g - options.w_motion * m + options.w_diversity * diversity[i];
  }
  return max_gain;
}

/// The candidates' gains from the learned model (their feature rows through it) and utilities;
/// returns the largest gain, or the model's error (the candidates' gains are then unchanged).
Result<double> ScoreWithModel(const PlanningRequest& request, const GainGrid& grid,
                              const AvpNbvOptions& options, const LearnedGainModel& model,
                              std::vector<ViewCandidate>& candidates) {
  const std::vector<size_t> reachable = Reachable(candidates);
  std::vector<ViewCandidate> scored;
  scored.reserve(reachable.size());
  for (size_t i : reachable) scored.push_back(candidates[i]);
  AVP_ASSIGN_OR_RETURN(const ViewFeatureExtractor features,
                       ViewFeatureExtractor::Build(request, grid));
  AVP_ASSIGN_OR_RETURN(const std::vector<float> predicted,
                       model.Predict(features.Compute(scored), scored.size()));
  for (size_t j = 0; j < reachable.size(); ++j) {
    candidates[reachable[j]].gain = static_cast<double>(predicted[j]);
  }
  return SetUtilities(options, reachable,
                      ViewpointDiversity(candidates, request.fused_views, options.diversity_m),
                      candidates);
}

/// The candidates' gains (in parallel over candidates, each independent) and utilities; returns
/// the largest gain. With coarse_ray_stride_px, every reachable candidate is first scored with the
/// coarse rays (their gain scaled to the fine ray count), then the refine_top best by that utility
/// again with the fine rays.
double ScoreCandidates(const PlanningRequest& request, const GainGrid& grid,
                       const AvpNbvOptions& options, std::vector<ViewCandidate>& candidates) {
  const std::vector<Eigen::Vector3d> fine = RayDirections(request.K, options.ray_stride_px);
  const CorePrior prior = CorePrior::Tabulated(grid.roi(), grid.voxel_size_m(), options);
  const GainParams params(options, grid.voxel_size_m());
  const std::vector<size_t> reachable = Reachable(candidates);
  const std::vector<double> diversity =
      ViewpointDiversity(candidates, request.fused_views, options.diversity_m);
  auto score = [&]() { return SetUtilities(options, reachable, diversity, candidates); };
  // Gains of the candidates `which` indexes, over `dirs` times `scale`.
  auto gains = [&](const std::vector<size_t>& which, const std::vector<Eigen::Vector3d>& dirs,
                   double scale) {
    ParallelFor(which.size(), [&](size_t j) {
      ViewCandidate& c = candidates[which[j]];
      c.gain = ViewGain(grid, prior, params, options, c, dirs, scale);
    });
  };
  const bool coarse_to_fine = options.coarse_ray_stride_px > options.ray_stride_px &&
                              reachable.size() > static_cast<size_t>(options.refine_top);
  if (coarse_to_fine) {
    const std::vector<Eigen::Vector3d> coarse =
        RayDirections(request.K, options.coarse_ray_stride_px);
    gains(reachable, coarse, static_cast<double>(fine.size()) / static_cast<double>(coarse.size()));
    score();
    std::vector<size_t> order = reachable;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return candidates[a].utility > candidates[b].utility;
    });
    order.resize(static_cast<size_t>(options.refine_top));
    gains(order, fine, 1.0);
  } else {
    gains(reachable, fine, 1.0);
  }
  return score();
}

/// The voxels a camera at X_WC would reveal with their gain contributions (keys packed, sorted,
/// each once), over the rays `dirs`.
std::vector<KeyedContribution> RevealedVoxels(const GainGrid& grid, const CorePrior& prior,
                                              const GainParams& params, double max_range_m,
                                              const RigidTransform& X_WC,
                                              const std::vector<Eigen::Vector3d>& dirs) {
  std::vector<KeyedContribution> out;
  const KeySink sink{&out};
  for (const Eigen::Vector3d& d_C : dirs) {
    RayGain(grid, prior, X_WC.translation(), X_WC * (max_range_m * d_C), params, sink);
  }
  std::sort(out.begin(), out.end());
  size_t w = 0;
  for (size_t r = 0; r < out.size(); ++r) {
    if (w > 0 && out[w - 1].first == out[r].first) {
      out[w - 1].second += out[r].second;
    } else {
      out[w++] = out[r];
    }
  }
  out.resize(w);
  return out;
}

/// Non-myopic choice (AvpNbvOptions::lookahead_views): adds to the utility of each of the
/// lookahead_top best candidates the discounted value of the views that would best follow it.
void AddLookahead(const PlanningRequest& request, const GainGrid& grid,
                  const AvpNbvOptions& options, std::vector<ViewCandidate>& candidates) {
  const int depth = std::min(options.lookahead_views, request.views_total - 1 - request.view_index);
  std::vector<size_t> top = Reachable(candidates);
  double max_gain = 0.0;
  for (size_t i : top) max_gain = std::max(max_gain, candidates[i].gain);
  if (depth <= 0 || top.size() < 2 || !(max_gain > 0.0)) return;
  std::stable_sort(top.begin(), top.end(), [&](size_t a, size_t b) {
    return candidates[a].utility > candidates[b].utility;
  });
  top.resize(std::min(top.size(), static_cast<size_t>(options.lookahead_top)));
  // The coarse rays, but never finer than every 40th pixel (16 x 12 rays on a 640 x 480 camera):
  // each of up to 64 candidates keeps the list of voxels its rays reveal.
  constexpr int kMinStridePx = 40;
  const std::vector<Eigen::Vector3d> dirs = RayDirections(
      request.K, std::max({kMinStridePx, options.coarse_ray_stride_px, options.ray_stride_px}));
  const CorePrior prior = CorePrior::Tabulated(grid.roi(), grid.voxel_size_m(), options);
  const GainParams params(options, grid.voxel_size_m());
  std::vector<std::vector<KeyedContribution>> reveal(top.size());
  std::vector<double> total(top.size(), 0.0);
  ParallelFor(top.size(), [&](size_t a) {
    reveal[a] =
        RevealedVoxels(grid, prior, params, options.max_range_m, candidates[top[a]].X_WC, dirs);
    for (const KeyedContribution& kc : reveal[a]) total[a] += kc.second;
  });
  std::vector<double> bonus(top.size(), 0.0);
  ParallelFor(top.size(), [&](size_t a) {
    std::unordered_set<uint64_t> seen;
    for (const KeyedContribution& kc : reveal[a]) seen.insert(kc.first);
    std::vector<bool> used(top.size(), false);
    used[a] = true;
    for (int t = 0; t < depth; ++t) {
      size_t best = top.size();
      double best_value = 0.0;
      for (size_t b = 0; b < top.size(); ++b) {
        if (used[b]) continue;
        double covered = 0.0;
        for (const KeyedContribution& kc : reveal[b]) {
          if (seen.count(kc.first) > 0) covered += kc.second;
        }
        const double fresh = total[b] > 0.0 ? 1.0 - covered / total[b] : 1.0;
        const double value = candidates[top[b]].gain / max_gain * fresh;
        if (value > best_value) {
          best_value = value;
          best = b;
        }
      }
      if (best == top.size()) break;
      bonus[a] += best_value;
      used[best] = true;
      for (const KeyedContribution& kc : reveal[best]) seen.insert(kc.first);
    }
  });
  for (size_t a = 0; a < top.size(); ++a) {
    candidates[top[a]].utility += options.lookahead_discount * bonus[a];
  }
}

/// The stopping rules: the best gain under min_gain_bits, or under min_gain_fraction of the
/// episode's first plan's (`first_max_gain`, set on the episode's first plan).
void ApplyStoppingRules(const AvpNbvOptions& options, const PlanningRequest& request,
                        double max_gain, double& first_max_gain, PlanResult& result) {
  if (result.status.ok() && options.min_gain_bits > 0.0 && max_gain < options.min_gain_bits) {
    result.stop = true;
    result.stop_reason =
        fmt::format("best expected gain {:.3f} bits is below the stopping threshold {:.3f} bits",
                    max_gain, options.min_gain_bits);
  }
  // The episode's first plan sets the scale of the relative rule (a new episode starts again at
  // view 1).
  if (request.view_index <= 1 || !std::isfinite(first_max_gain)) first_max_gain = max_gain;
  if (result.status.ok() && !result.stop && options.min_gain_fraction > 0.0 &&
      max_gain < options.min_gain_fraction * first_max_gain) {
    result.stop = true;
    result.stop_reason = fmt::format(
        "best expected gain {:.3f} bits is below the stopping threshold {:.3f} x the first "
        "plan's {:.3f} bits",
        max_gain, options.min_gain_fraction, first_max_gain);
  }
}

}  // namespace

AvpNbvPlanner::AvpNbvPlanner(const AvpNbvOptions& options,
                             std::shared_ptr<const LearnedGainModel> model)
    : options_(options), model_(std::move(model)) {
  if (const Status s = options.Validate(); !s.ok()) throw Error(s.ToString());
  if (!model_ && !options.gain_model.empty()) {
    Result<std::shared_ptr<const LearnedGainModel>> loaded =
        LearnedGainModel::Load(ResolveGainModelPath(options.gain_model));
    if (!loaded.ok()) throw Error(loaded.status().ToString());
    model_ = std::move(*loaded);
  }
}

PlanResult AvpNbvPlanner::Plan(const PlanningRequest& request, Rng& rng) {
  PlanResult result;
  if (Status s = ValidateRequest(request); !s.ok()) {
    result.status = s;
    return result;
  }
  Result<GainGrid> grid =
      GainGrid::Build(*request.map, request.target_class, request.roi, options_.grid);
  if (!grid.ok()) {
    result.status = grid.status();
    return result;
  }
  const std::vector<ViewTarget> targets = FindViewTargets(request, *grid, options_.candidates);
  std::vector<ViewCandidate> candidates =
      GenerateShellCandidates(request, *grid, targets, options_.candidates, rng);
  const size_t generated = candidates.size();
  double max_gain = 0.0;
  std::vector<std::string> warnings;
  if (model_) {
    const Result<double> learned = ScoreWithModel(request, *grid, options_, *model_, candidates);
    if (learned.ok()) {
      max_gain = *learned;
    } else {
      warnings.push_back(fmt::format(
          "the learned gain failed ({}): this step is ranked with the hand-written gain",
          learned.status().ToString()));
    }
  }
  if (!model_ || !warnings.empty()) {
    max_gain = ScoreCandidates(request, *grid, options_, candidates);
  }
  AddLookahead(request, *grid, options_, candidates);
  result = RankCandidates(std::move(candidates), generated, name());
  result.warnings = std::move(warnings);
  ApplyStoppingRules(options_, request, max_gain, first_max_gain_, result);
  return result;
}

}  // namespace avp::planning
