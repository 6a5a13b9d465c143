#pragma once

#include <cstddef>
#include <limits>
#include <span>
#include <string>

namespace avp::eval {

/// Mean, spread and 95 % confidence interval of a sample (e.g. one metric over seeds).
struct Summary {
  /// Finite values used; non-finite ones (NaN, +-inf) are left out and counted in `skipped`.
  size_t n = 0;
  size_t skipped = 0;
  /// Arithmetic mean; NaN when n = 0.
  double mean = std::numeric_limits<double>::quiet_NaN();
  /// Sample standard deviation (n - 1 in the denominator); NaN when n < 2.
  double sd = std::numeric_limits<double>::quiet_NaN();
  /// The 95 % confidence interval of the mean, [ci_lo, ci_hi]: a percentile bootstrap
  /// (kBootstrapResamples resamples of the values with replacement, drawn from a fixed seed: the
  /// same interval on every machine). It always lies within the values' [min, max], so a metric
  /// bounded to [0, 1] (F1, a fraction found) or [-1, 1] (a paired difference of such) keeps its
  /// interval inside its range, as Student's t does not at small n. NaN when n < 2 (one value says
  /// nothing about the spread); with n < kSmallSample it is as wide as a few values make it (the
  /// tables and plots mark small n).
  double ci_lo = std::numeric_limits<double>::quiet_NaN();
  double ci_hi = std::numeric_limits<double>::quiet_NaN();
  /// Whether the interval exists (n >= 2).
  bool has_interval() const { return n >= 2; }
};

/// Resamples of Summarize's bootstrap interval.
inline constexpr size_t kBootstrapResamples = 4000;
/// Below this many values an interval is marked as resting on a small sample.
inline constexpr size_t kSmallSample = 5;

/// Summarises `values` (see Summary): the mean, the standard deviation (two passes, in order) and
/// the bootstrap interval of the mean.
Summary Summarize(std::span<const double> values);

/// "0.423 [0.310, 0.551]": the mean and its 95 % interval at `decimals` decimals (`sign`: "+0.12");
/// "0.700 (n = 1, no interval)" below two values; "–" for none.
std::string FormatMeanInterval(const Summary& s, int decimals = 3, bool sign = false);
/// The same for a summary kept as its mean, interval ends and n (a table's cell).
std::string FormatMeanInterval(double mean, double ci_lo, double ci_hi, size_t n, int decimals = 3,
                               bool sign = false);

/// The verdict of a paired difference (a - b, seed by seed): "ahead" when its whole 95 % interval
/// is above 0, "behind" when below, "tied" when it holds 0, "n/a" below two pairs.
std::string PairedVerdict(const Summary& difference);

/// The median of the finite values (the mean of the middle two for an even count); NaN when
/// there are none.
double Median(std::span<const double> values);

/// The two-sided 95 % quantile of Student's t, t(0.975, dof): exact to 1e-6 for dof = 1..30 (a
/// table), 1.96 (the normal quantile) beyond; NaN for dof = 0.
double StudentT975(size_t dof);

/// Spearman's rank correlation of two samples of equal length: Pearson's correlation of their
/// ranks, ties sharing their mean rank. NaN when the lengths differ, n < 2, or either sample is
/// constant (no ranking to compare).
double SpearmanRankCorrelation(std::span<const double> a, std::span<const double> b);

}  // namespace avp::eval
