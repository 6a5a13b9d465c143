#pragma once

#include <cstddef>
#include <limits>
#include <span>

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
  /// Half-width of the 95 % confidence interval of the mean, t(0.975, n - 1) * sd / sqrt(n); NaN
  /// when n < 2 (one value says nothing about the spread).
  double ci95 = std::numeric_limits<double>::quiet_NaN();
};

/// Summarises `values` (see Summary). Two passes (mean, then squared deviations), in order.
Summary Summarize(std::span<const double> values);

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
