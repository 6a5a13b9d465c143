#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include <avp/robot/trajectory.h>

namespace avp::robot {

namespace {

/// A rest-to-rest move along s ∈ [0, 1]: accelerate at `a` to `v`, cruise, decelerate.
struct Profile {
  double a = 0.0;         ///< ds/dt²
  double v = 0.0;         ///< peak ds/dt
  double t_ramp = 0.0;    ///< time to reach v
  double duration = 0.0;  ///< whole move

  static Profile Of(double v_max, double a_max) {
    Profile p;
    p.a = a_max;
    if (v_max * v_max / a_max <= 1.0) {  // trapezoid: cruise at v_max
      p.v = v_max;
      p.t_ramp = v_max / a_max;
      p.duration = 1.0 / v_max + v_max / a_max;
    } else {  // triangle: the peak is reached half way
      p.v = std::sqrt(a_max);
      p.t_ramp = 1.0 / p.v;
      p.duration = 2.0 * p.t_ramp;
    }
    return p;
  }

  /// s and ds/dt at time t in [0, duration].
  std::pair<double, double> At(double t) const {
    if (t <= 0.0) return {0.0, 0.0};
    if (t >= duration) return {1.0, 0.0};
    if (t < t_ramp) return {0.5 * a * t * t, a * t};
    const double t_decel = duration - t_ramp;
    if (t <= t_decel) return {0.5 * a * t_ramp * t_ramp + v * (t - t_ramp), v};
    const double r = duration - t;
    return {1.0 - 0.5 * a * r * r, a * r};
  }
};

Status CheckPath(const ArmModel& arm, const std::vector<Eigen::VectorXd>& path,
                 double velocity_scaling, double acceleration_scaling, double sample_period_s) {
  if (path.empty()) return InvalidArgumentError("time parameterization: the path has no vertex");
  for (const auto& [name, value] : {std::pair{"velocity_scaling", velocity_scaling},
                                    std::pair{"acceleration_scaling", acceleration_scaling}}) {
    if (!(value > 0.0 && value <= 1.0)) {
      return InvalidArgumentError(
          fmt::format("time parameterization: {} ({}) must be in (0, 1]", name, value));
    }
  }
  if (!(sample_period_s > 0.0) || !std::isfinite(sample_period_s)) {
    return InvalidArgumentError(fmt::format(
        "time parameterization: sample_period_s ({}) must be finite and > 0", sample_period_s));
  }
  for (size_t i = 0; i < path.size(); ++i) {
    if (path[i].size() != arm.num_joints() || !path[i].allFinite()) {
      return InvalidArgumentError(fmt::format(
          "time parameterization: vertex {} has {} entries ({} joints) or a non-finite one", i,
          path[i].size(), arm.num_joints()));
    }
  }
  return Status::Ok();
}

}  // namespace

Status JointTrajectory::Validate(const ArmModel& arm) const {
  const int n = arm.num_joints();
  if (joint_names != arm.joint_names()) {
    return InvalidArgumentError(fmt::format("trajectory joints ({}) are not the arm's ({})",
                                            fmt::join(joint_names, ", "),
                                            fmt::join(arm.joint_names(), ", ")));
  }
  if (points.size() < 2) {
    return InvalidArgumentError(
        fmt::format("trajectory has {} point(s); at least 2 are needed", points.size()));
  }
  for (size_t k = 0; k < points.size(); ++k) {
    const TrajectoryPoint& p = points[k];
    if (p.q.size() != n || p.qd.size() != n || !p.q.allFinite() || !p.qd.allFinite()) {
      return InvalidArgumentError(fmt::format(
          "trajectory point {}: {} positions and {} velocities for {} joints, all finite", k,
          p.q.size(), p.qd.size(), n));
    }
    if (const Status s = arm.CheckJoints(p.q); !s.ok()) {
      return s.WithContext(fmt::format("trajectory point {}", k));
    }
    if (k == 0 ? p.t_s != 0.0 : !(p.t_s > points[k - 1].t_s) || !std::isfinite(p.t_s)) {
      return InvalidArgumentError(fmt::format(
          "trajectory point {}: time_from_start {} s must be {}", k, p.t_s,
          k == 0 ? "0"
                 : fmt::format("finite and after the previous point's {} s", points[k - 1].t_s)));
    }
    for (int i = 0; i < n; ++i) {
      const double limit = arm.joints()[static_cast<size_t>(i)].velocity_limit;
      if (limit > 0.0 && std::abs(p.qd[i]) > 1.01 * limit) {
        return InvalidArgumentError(
            fmt::format("trajectory point {}: joint '{}' velocity {:.4g} exceeds its limit {:.4g}",
                        k, arm.joint_names()[static_cast<size_t>(i)], p.qd[i], limit));
      }
    }
  }
  return Status::Ok();
}

Result<JointTrajectory> TimeParameterize(const ArmModel& arm,
                                         const std::vector<Eigen::VectorXd>& path,
                                         double velocity_scaling, double acceleration_scaling,
                                         double sample_period_s) {
  AVP_RETURN_IF_ERROR(
      CheckPath(arm, path, velocity_scaling, acceleration_scaling, sample_period_s));
  const int n = arm.num_joints();
  const double accel = acceleration_scaling * arm.config().joint_acceleration_limit;
  JointTrajectory traj;
  traj.joint_names = arm.joint_names();
  traj.points.push_back({path.front(), Eigen::VectorXd::Zero(n), 0.0});
  double t0 = 0.0;
  for (size_t k = 1; k < path.size(); ++k) {
    const Eigen::VectorXd dq = path[k] - path[k - 1];
    double v_s = std::numeric_limits<double>::infinity();
    double a_s = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {
      const double d = std::abs(dq[i]);
      if (d < 1e-12) continue;
      const double v_limit = arm.joints()[static_cast<size_t>(i)].velocity_limit;
      if (!(v_limit > 0.0)) {
        return InvalidArgumentError(fmt::format(
            "time parameterization: joint '{}' moves but the URDF gives it no velocity limit",
            arm.joint_names()[static_cast<size_t>(i)]));
      }
      v_s = std::min(v_s, velocity_scaling * v_limit / d);
      a_s = std::min(a_s, accel / d);
    }
    if (!std::isfinite(v_s)) continue;  // a repeated vertex
    const Profile profile = Profile::Of(v_s, a_s);
    // Bounded before sampling: a tiny limit cannot make millions of points.
    constexpr double kMaxPoints = 100000;
    if (!(profile.duration / sample_period_s + static_cast<double>(traj.points.size()) <=
          kMaxPoints)) {
      return InvalidArgumentError(fmt::format(
          "time parameterization: segment {} takes {:.4g} s, more than {} points of {} s "
          "(velocity or acceleration limits near 0?)",
          k, profile.duration, kMaxPoints, sample_period_s));
    }
    for (double t = sample_period_s; t < profile.duration - 1e-9; t += sample_period_s) {
      const auto [s, ds] = profile.At(t);
      traj.points.push_back({path[k - 1] + s * dq, ds * dq, t0 + t});
    }
    t0 += profile.duration;
    traj.points.push_back({path[k], Eigen::VectorXd::Zero(n), t0});
  }
  if (traj.points.size() == 1) traj.points.push_back({path.back(), Eigen::VectorXd::Zero(n), 1e-3});
  return traj;
}

int64_t TimeNs(const TrajectoryPoint& point) { return static_cast<int64_t>(point.t_s * 1e9); }

std::vector<int64_t> JointTrajectory::times_ns() const {
  std::vector<int64_t> t;
  t.reserve(points.size());
  for (const TrajectoryPoint& p : points) t.push_back(TimeNs(p));
  return t;
}

Eigen::VectorXd JointsAt(std::span<const Eigen::VectorXd> q, std::span<const int64_t> t_ns,
                         int64_t at_ns) {
  if (at_ns <= t_ns.front()) return q.front();
  for (size_t i = 1; i < q.size(); ++i) {
    if (at_ns > t_ns[i]) continue;
    const int64_t span = t_ns[i] - t_ns[i - 1];
    if (span <= 0) return q[i];
    const double a = static_cast<double>(at_ns - t_ns[i - 1]) / static_cast<double>(span);
    return q[i - 1] + a * (q[i] - q[i - 1]);
  }
  return q.back();
}

std::vector<int64_t> FrameTimesNs(int64_t duration_ns, double rate_hz) {
  std::vector<int64_t> times;
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) return times;
  for (int64_t k = 1;; ++k) {
    // Compared before rounding too: a tiny rate would overflow the rounding (and never end).
    const double at = static_cast<double>(k) * 1e9 / rate_hz;
    if (!(at < static_cast<double>(duration_ns) + 1.0)) break;
    const auto t = static_cast<int64_t>(std::llround(at));
    if (t >= duration_ns) break;
    times.push_back(t);
  }
  return times;
}

std::vector<FrameAlong> FramesAlong(const JointTrajectory& trajectory, double rate_hz) {
  std::vector<FrameAlong> frames;
  if (trajectory.points.size() < 2) return frames;
  const std::vector<int64_t> t_ns = trajectory.times_ns();
  std::vector<Eigen::VectorXd> q;
  q.reserve(trajectory.points.size());
  for (const TrajectoryPoint& p : trajectory.points) q.push_back(p.q);
  const std::vector<int64_t> times = FrameTimesNs(t_ns.back(), rate_hz);
  frames.reserve(times.size());
  for (size_t i = 0; i < times.size(); ++i) {
    frames.push_back({static_cast<int>(i + 1), times[i], JointsAt(q, t_ns, times[i])});
  }
  return frames;
}

}  // namespace avp::robot
