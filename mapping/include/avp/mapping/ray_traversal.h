#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>

#include <Eigen/Core>

#include <avp/core/voxel_key.h>

namespace avp::mapping {

class PlanningSnapshot;  // bench_map's (benchmarks/planning_snapshot.h)

/// Exact voxel traversal of a segment, in integer arithmetic.
///
/// Both end points are floored once onto a fixed-point lattice of 2^-16 voxel (which keeps each in
/// its VoxelKey::FromPoint voxel); from then on every
/// decision is exact: the walker compares the crossing parameters t_i = N_i / A_i of the three axes
/// by cross-multiplication (N_i * A_j vs N_j * A_i, maintained incrementally in 64-bit integers),
/// so it never drifts, visits exactly the 6-connected chain of voxels the segment passes through,
/// and always ends in the end point's voxel after exactly |dk_x| + |dk_y| + |dk_z| steps. When the
/// segment crosses an edge or corner exactly (ties), the lower axis (x, then y, then z) steps
/// first. Voxels follow VoxelKey's lattice (floor(p / voxel)), i.e. OctoMap's.
class RayWalker {
 public:
  static constexpr int kFractionBits = 16;
  /// Longest segment accepted, in voxels (32 m at 2 mm): keeps every product inside 62 bits.
  static constexpr int64_t kMaxLengthVoxels = int64_t{1} << 14;

  RayWalker(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double voxel_size_m) {
    // p * (1 / s) exactly as VoxelKey::FromPoint and OctoMap's coordToKey compute it; the scaling
    // by 2^16 is exact, so floor() keeps every end point in the same voxel as FromPoint.
    const double inv = 1.0 / voxel_size_m;
    constexpr double kScale = static_cast<double>(int64_t{1} << kFractionBits);
    int64_t u0[3], u1[3];
    for (int i = 0; i < 3; ++i) {
      const double a = from[i] * inv * kScale;
      const double b = to[i] * inv * kScale;
      constexpr double kLimit = static_cast<double>(int64_t{1} << (23 + kFractionBits));
      if (!(std::abs(a) < kLimit && std::abs(b) < kLimit)) {
        ok_ = false;
        remaining_ = 0;
        return;
      }
      u0[i] = FloorToInt(a);
      u1[i] = FloorToInt(b);
    }
    constexpr int64_t kOne = int64_t{1} << kFractionBits;
    int64_t n[3], a[3];
    remaining_ = 0;
    for (int i = 0; i < 3; ++i) {
      const int64_t k0 = u0[i] >> kFractionBits;  // floor (arithmetic shift)
      const int64_t k1 = u1[i] >> kFractionBits;
      key_[i] = static_cast<int32_t>(k0);
      const int64_t d = u1[i] - u0[i];
      a[i] = d < 0 ? -d : d;
      step_[i] = d > 0 ? 1 : (d < 0 ? -1 : 0);
      n[i] =
          d > 0 ? ((k0 + 1) << kFractionBits) - u0[i] : (d < 0 ? u0[i] - (k0 << kFractionBits) : 1);
      axis_remaining_[i] = k1 > k0 ? k1 - k0 : k0 - k1;
      remaining_ += axis_remaining_[i];
      if (a[i] > kMaxLengthVoxels * kOne) ok_ = false;
    }
    if (!ok_) {
      remaining_ = 0;
      return;
    }
    // Raw pairwise differences for the unguarded loop (PlanningSnapshot::CastRay): axis i steps
    // before axis j iff d <= 0. An exhausted axis's next crossing lies at t >= 1, every pending
    // crossing at t <= 1, so without guards only a tie at t == 1 could pick an exhausted axis.
    diff_[0] = n[0] * a[1] - n[1] * a[0];
    diff_[1] = n[0] * a[2] - n[2] * a[0];
    diff_[2] = n[1] * a[2] - n[2] * a[1];
    for (int i = 0; i < 3; ++i) {
      if (a[i] > 0 && n[i] + axis_remaining_[i] * kOne == a[i]) exhausted_tie_ = true;
    }
    // p_[i][j] = N_i * A_j: t_i <= t_j  <=>  p_[i][j] <= p_[j][i].
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        p_[i][j] = n[i] * a[j];
        inc_[i][j] = kOne * a[j];
      }
      if (axis_remaining_[i] == 0) p_[i][(i + 1) % 3] = p_[i][(i + 2) % 3] = kNever;
    }
  }

  /// False when an end point is outside the key range or the segment is longer than
  /// kMaxLengthVoxels; such a walker visits nothing.
  bool ok() const { return ok_; }
  VoxelKey key() const { return {key_[0], key_[1], key_[2]}; }
  /// One coordinate of key() (0: x, 1: y, 2: z).
  int32_t key_axis(int axis) const { return key_[axis]; }
  /// Steps left until the end point's voxel; 0 when the current voxel is the last.
  int64_t remaining() const { return remaining_; }
  /// Axis of the last step (0, 1, 2), -1 before the first.
  int last_axis() const { return last_axis_; }
  int step(int axis) const { return step_[axis]; }

  /// Calls fn(const VoxelKey&) -> bool for the current voxel and each next one up to, not
  /// including, the end point's voxel (remaining() calls), in order, until fn returns false:
  /// exactly the keys of key() and Step(), with the walker's state copied into locals (registers)
  /// and a branchless axis choice (PlanningSnapshot::CastRayGuarded walks with it; Step keeps its
  /// state in arrays indexed by the axis, and reads of key() after it stall on store forwarding).
  /// The walker itself does not move. Returns the calls made.
  template <typename Fn>
  int64_t ForEachKeyBeforeEnd(Fn&& fn) const {
    int64_t left = remaining_;
    int32_t kx = key_[0], ky = key_[1], kz = key_[2];
    const int32_t sx = step_[0], sy = step_[1], sz = step_[2];
    int64_t rx = axis_remaining_[0], ry = axis_remaining_[1], rz = axis_remaining_[2];
    int64_t pxy = p_[0][1], pxz = p_[0][2], pyx = p_[1][0], pyz = p_[1][2], pzx = p_[2][0],
            pzy = p_[2][1];
    const int64_t ixy = inc_[0][1], ixz = inc_[0][2], iyx = inc_[1][0], iyz = inc_[1][2],
                  izx = inc_[2][0], izy = inc_[2][1];
    int64_t calls = 0;
    while (left > 0) {
      ++calls;
      if (!fn(VoxelKey{kx, ky, kz})) break;
      --left;
      // Step()'s choice: axis = xy ? (xz ? x : z) : (yz ? y : z).
      const bool xy = pxy <= pyx, xz = pxz <= pzx, yz = pyz <= pzy;
      const bool x_first = xy & xz;
      const bool y_first = !xy & yz;
      const int64_t mx = -static_cast<int64_t>(x_first), my = -static_cast<int64_t>(y_first),
                    mz = ~(mx | my);
      kx += sx & static_cast<int32_t>(mx);
      ky += sy & static_cast<int32_t>(my);
      kz += sz & static_cast<int32_t>(mz);
      rx += mx;  // -1 on the stepped axis
      ry += my;
      rz += mz;
      pxy += ixy & mx;
      pxz += ixz & mx;
      pyx += iyx & my;
      pyz += iyz & my;
      pzx += izx & mz;
      pzy += izy & mz;
      // An exhausted axis is never chosen again (it is never stepped after, so kNever stays).
      pxy = rx == 0 ? kNever : pxy;
      pxz = rx == 0 ? kNever : pxz;
      pyx = ry == 0 ? kNever : pyx;
      pyz = ry == 0 ? kNever : pyz;
      pzx = rz == 0 ? kNever : pzx;
      pzy = rz == 0 ? kNever : pzy;
    }
    return calls;
  }

  /// The walk's decisions as three pairwise differences, for loops that keep them in registers:
  /// axis i steps before axis j iff d_ij <= 0, and a step along i adds inc_j to d_ij and
  /// subtracts inc_i from d_ji (inc_i = 2^16 A_i). Without exhaustion guards these give Step()'s
  /// walk for remaining() steps exactly when !exhausted_tie(): an exhausted axis's next crossing
  /// then lies beyond the end point, every pending one before it.
  struct Differences {
    int64_t dxy, dxz, dyz;
    int64_t inc_x, inc_y, inc_z;
    int step_x, step_y, step_z;  ///< -1, 0 or 1

    /// One step, branch-free: updates the differences and returns the all-ones mask of the axis
    /// it steps along in that axis's slot, 0 in the others.
    [[gnu::always_inline]] std::array<int64_t, 3> Step() {
      // All-ones masks of d <= 0 (|d| < 2^62, so d - 1 cannot overflow).
      const int64_t le_xy = (dxy - 1) >> 63, le_xz = (dxz - 1) >> 63, le_yz = (dyz - 1) >> 63;
      const int64_t mx = le_xy & le_xz, my = ~mx & le_yz, mz = ~(mx | my);
      dxy += (inc_y & mx) - (inc_x & my);
      dxz += (inc_z & mx) - (inc_x & mz);
      dyz += (inc_z & my) - (inc_y & mz);
      return {mx, my, mz};
    }
  };
  Differences differences() const {
    return {diff_[0],   diff_[1], diff_[2], inc_[1][0], inc_[0][1],
            inc_[0][2], step_[0], step_[1], step_[2]};
  }
  /// Some axis's next crossing after its last step lies exactly at the end point: the last steps
  /// follow the exhausted-axis rule, which differences() does not know.
  bool exhausted_tie() const { return exhausted_tie_; }

  /// Moves to the next voxel and returns the axis it stepped along. @pre remaining() > 0.
  int Step() {
    const bool xy = p_[0][1] <= p_[1][0];
    const bool xz = p_[0][2] <= p_[2][0];
    const bool yz = p_[1][2] <= p_[2][1];
    const int axis = xy ? (xz ? 0 : 2) : (yz ? 1 : 2);
    key_[axis] += step_[axis];
    --remaining_;
    last_axis_ = axis;
    const int j = (axis + 1) % 3;
    const int k = (axis + 2) % 3;
    if (--axis_remaining_[axis] == 0) {
      p_[axis][j] = p_[axis][k] = kNever;
    } else {
      p_[axis][j] += inc_[axis][j];
      p_[axis][k] += inc_[axis][k];
    }
    return axis;
  }

 private:
  /// floor(v) for |v| < 2^52, without a libm call (baseline x86-64 has no SSE4.1 round).
  static int64_t FloorToInt(double v) {
    const int64_t t = static_cast<int64_t>(v);  // truncates toward zero
    return t - static_cast<int64_t>(v < static_cast<double>(t));
  }

  // bench_map's PlanningSnapshot (benchmarks/planning_snapshot.h): its CastRay runs the same
  // decisions in registers.
  friend class PlanningSnapshot;
  static constexpr int64_t kNever = std::numeric_limits<int64_t>::max();
  bool ok_ = true;
  int32_t key_[3] = {0, 0, 0};
  int step_[3] = {0, 0, 0};
  int64_t axis_remaining_[3] = {0, 0, 0};
  int64_t remaining_ = 0;
  int last_axis_ = -1;
  int64_t p_[3][3] = {};
  int64_t inc_[3][3] = {};
  /// N_x A_y - N_y A_x, N_x A_z - N_z A_x, N_y A_z - N_z A_y (no kNever substitution).
  int64_t diff_[3] = {0, 0, 0};
  /// Some axis's first crossing after its last step lies exactly at the end point (t == 1): the
  /// unguarded decisions could pick it on a tie, so CastRay takes the guarded loop.
  bool exhausted_tie_ = false;
};

/// The voxel of a point as RayWalker sees it: always VoxelKey::FromPoint (end points are floored
/// onto the 2^-16 voxel lattice, which never moves them across a voxel face).
inline VoxelKey FixedPointKey(const Eigen::Vector3d& p, double voxel_size_m) {
  return VoxelKey::FromPoint(p, voxel_size_m);
}

/// Visits the voxels of the segment [from, to] in order, from the voxel of `from` to the voxel of
/// `to` inclusive, calling visit(const VoxelKey&) -> bool; stops early when it returns false.
/// Returns the number of voxels visited (0 if the walker is not ok()).
template <typename Visitor>
int64_t TraverseRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double voxel_size_m,
                    Visitor&& visit) {
  RayWalker w(from, to, voxel_size_m);
  if (!w.ok()) return 0;
  int64_t visited = 0;
  while (true) {
    ++visited;
    if (!visit(w.key())) break;
    if (w.remaining() == 0) break;
    w.Step();
  }
  return visited;
}

}  // namespace avp::mapping
