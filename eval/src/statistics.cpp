#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/eval/statistics.h>

namespace avp::eval {

namespace {

/// t(0.975, dof) for dof = 1..30.
constexpr std::array<double, 30> kT975 = {
    12.706205, 4.302653, 3.182446, 2.776445, 2.570582, 2.446912, 2.364624, 2.306004,
    2.262157,  2.228139, 2.200985, 2.178813, 2.160369, 2.144787, 2.131450, 2.119905,
    2.109816,  2.100922, 2.093024, 2.085963, 2.079614, 2.073873, 2.068658, 2.063899,
    2.059539,  2.055529, 2.051831, 2.048407, 2.045230, 2.042272};

/// Ranks 1..n of `v`, ties sharing their mean rank.
std::vector<double> Ranks(std::span<const double> v) {
  std::vector<size_t> order(v.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t i, size_t j) { return v[i] < v[j]; });
  std::vector<double> rank(v.size());
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    while (j + 1 < order.size() && v[order[j + 1]] == v[order[i]]) ++j;
    const double mean_rank = 0.5 * static_cast<double>(i + j) + 1.0;
    for (size_t k = i; k <= j; ++k) rank[order[k]] = mean_rank;
    i = j + 1;
  }
  return rank;
}

/// SplitMix64: a fixed, portable stream (the same draws with every compiler and library,
/// which std::uniform_int_distribution does not promise).
uint64_t SplitMix64(uint64_t& state) {
  uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// A uniform index in [0, n), without modulo bias.
size_t UniformIndex(uint64_t& state, size_t n) {
  const uint64_t range = static_cast<uint64_t>(n);
  const uint64_t limit =
      std::numeric_limits<uint64_t>::max() - std::numeric_limits<uint64_t>::max() % range;
  uint64_t x = SplitMix64(state);
  while (x >= limit) x = SplitMix64(state);
  return static_cast<size_t>(x % range);
}

/// The percentile bootstrap's 95 % interval of the mean of `v` (n >= 2): the 2.5 % and 97.5 %
/// quantiles of kBootstrapResamples resampled means, nearest rank; the seed is fixed, so equal
/// samples give equal intervals.
std::pair<double, double> BootstrapMeanInterval95(const std::vector<double>& v) {
  uint64_t state = 0x61767062'6f6f7473ULL;  // "avpboots"
  std::vector<double> means(kBootstrapResamples);
  for (double& m : means) {
    double sum = 0.0;
    for (size_t i = 0; i < v.size(); ++i) sum += v[UniformIndex(state, v.size())];
    m = sum / static_cast<double>(v.size());
  }
  std::sort(means.begin(), means.end());
  const auto at = [&](double q) {
    const double rank = std::ceil(q * static_cast<double>(means.size()));
    return means[static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(means.size()))) - 1];
  };
  // The resampled means lie within [min, max] of v; so do their quantiles.
  return {at(0.025), at(0.975)};
}

}  // namespace

double SpearmanRankCorrelation(std::span<const double> a, std::span<const double> b) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (a.size() != b.size() || a.size() < 2) return nan;
  const std::vector<double> ra = Ranks(a), rb = Ranks(b);
  const double n = static_cast<double>(a.size());
  const double mean = 0.5 * (n + 1.0);
  double sab = 0.0, saa = 0.0, sbb = 0.0;
  for (size_t i = 0; i < ra.size(); ++i) {
    sab += (ra[i] - mean) * (rb[i] - mean);
    saa += (ra[i] - mean) * (ra[i] - mean);
    sbb += (rb[i] - mean) * (rb[i] - mean);
  }
  if (saa == 0.0 || sbb == 0.0) return nan;
  return sab / std::sqrt(saa * sbb);
}

double StudentT975(size_t dof) {
  if (dof == 0) return std::numeric_limits<double>::quiet_NaN();
  if (dof <= kT975.size()) return kT975[dof - 1];
  return 1.96;
}

double Median(std::span<const double> values) {
  std::vector<double> v;
  v.reserve(values.size());
  for (double x : values) {
    if (std::isfinite(x)) v.push_back(x);
  }
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  if (v.size() % 2 == 1) return v[mid];
  const double upper = v[mid];
  const double lower = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
  return 0.5 * (lower + upper);
}

Summary Summarize(std::span<const double> values) {
  Summary s;
  double sum = 0.0;
  for (double v : values) {
    if (!std::isfinite(v)) {
      ++s.skipped;
      continue;
    }
    ++s.n;
    sum += v;
  }
  if (s.n == 0) return s;
  s.mean = sum / static_cast<double>(s.n);
  if (s.n < 2) return s;
  double squares = 0.0;
  for (double v : values) {
    if (std::isfinite(v)) squares += (v - s.mean) * (v - s.mean);
  }
  s.sd = std::sqrt(squares / static_cast<double>(s.n - 1));
  std::vector<double> finite;
  finite.reserve(s.n);
  for (double v : values) {
    if (std::isfinite(v)) finite.push_back(v);
  }
  std::tie(s.ci_lo, s.ci_hi) = BootstrapMeanInterval95(finite);
  return s;
}

std::string FormatMeanInterval(const Summary& s, int decimals, bool sign) {
  if (s.n == 0) return "–";
  const auto num = [&](double v) {
    return sign ? fmt::format("{:+.{}f}", v, decimals) : fmt::format("{:.{}f}", v, decimals);
  };
  if (!s.has_interval()) return fmt::format("{} (n = {}, no interval)", num(s.mean), s.n);
  return fmt::format("{} [{}, {}]", num(s.mean), num(s.ci_lo), num(s.ci_hi));
}

std::string FormatMeanInterval(double mean, double ci_lo, double ci_hi, size_t n, int decimals,
                               bool sign) {
  Summary s;
  s.n = n;
  s.mean = mean;
  s.ci_lo = ci_lo;
  s.ci_hi = ci_hi;
  return FormatMeanInterval(s, decimals, sign);
}

std::string PairedVerdict(const Summary& d) {
  if (!d.has_interval()) return "n/a";
  if (d.ci_lo > 0.0) return "ahead";
  if (d.ci_hi < 0.0) return "behind";
  return "tied";
}

}  // namespace avp::eval
