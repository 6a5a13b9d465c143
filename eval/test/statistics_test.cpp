// Summaries over runs: mean, sample standard deviation and the Student-t 95 % interval.
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include <avp/eval/statistics.h>

namespace avp::eval {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(StatisticsTest, TQuantilesMatchTables) {
  // t(0.975, dof) from standard tables (and tan(0.475 pi) for one degree of freedom).
  EXPECT_NEAR(StudentT975(1), std::tan(0.475 * M_PI), 1e-6);
  EXPECT_NEAR(StudentT975(2), 4.302653, 1e-6);
  EXPECT_NEAR(StudentT975(4), 2.776445, 1e-6);
  EXPECT_NEAR(StudentT975(9), 2.262157, 1e-6);
  EXPECT_NEAR(StudentT975(19), 2.093024, 1e-6);
  EXPECT_NEAR(StudentT975(30), 2.042272, 1e-6);
  EXPECT_EQ(StudentT975(31), 1.96);
  EXPECT_EQ(StudentT975(1000), 1.96);
  EXPECT_TRUE(std::isnan(StudentT975(0)));
  // Two degrees of freedom in closed form: t = (2 p - 1) / sqrt(2 p (1 - p)).
  const double p = 0.975;
  EXPECT_NEAR(StudentT975(2), (2 * p - 1) / std::sqrt(2 * p * (1 - p)), 1e-6);
  // The table decreases monotonically towards the normal quantile.
  for (size_t dof = 1; dof < 30; ++dof) EXPECT_GT(StudentT975(dof), StudentT975(dof + 1));
  EXPECT_GT(StudentT975(30), 1.96);
}

TEST(StatisticsTest, SummaryOfKnownSample) {
  const std::vector<double> v = {2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0};
  const Summary s = Summarize(v);
  EXPECT_EQ(s.n, 8u);
  EXPECT_EQ(s.skipped, 0u);
  EXPECT_DOUBLE_EQ(s.mean, 5.0);
  // Sum of squared deviations 32, sample variance 32 / 7.
  EXPECT_NEAR(s.sd, std::sqrt(32.0 / 7.0), 1e-12);
  // The bootstrap interval holds the mean, lies within the sample, and is the same every time.
  EXPECT_LT(s.ci_lo, s.mean);
  EXPECT_GT(s.ci_hi, s.mean);
  EXPECT_GE(s.ci_lo, 2.0);
  EXPECT_LE(s.ci_hi, 9.0);
  // Close to the normal theory's at this n: mean +- 1.96 sd / sqrt(n) = 5 +- 1.48.
  EXPECT_NEAR(s.ci_lo, 5.0 - 1.96 * s.sd * std::sqrt(7.0 / 8.0) / std::sqrt(8.0), 0.35);
  EXPECT_NEAR(s.ci_hi, 5.0 + 1.96 * s.sd * std::sqrt(7.0 / 8.0) / std::sqrt(8.0), 0.35);
  const Summary again = Summarize(v);
  EXPECT_EQ(again.ci_lo, s.ci_lo);
  EXPECT_EQ(again.ci_hi, s.ci_hi);
}

TEST(StatisticsTest, IntervalsOfFractionsStayWithinZeroAndOne) {
  // Three seeds of a fraction found: Student's t gives 0.333 +- 1.434, far outside [0, 1].
  const std::vector<double> found = {0.0, 0.0, 1.0};
  const Summary s = Summarize(found);
  EXPECT_NEAR(s.mean, 1.0 / 3.0, 1e-12);
  EXPECT_GE(s.ci_lo, 0.0);
  EXPECT_LE(s.ci_hi, 1.0);
  EXPECT_DOUBLE_EQ(s.ci_lo, 0.0);
  EXPECT_DOUBLE_EQ(s.ci_hi, 1.0);
  // Two values: the resampled means are a, (a + b) / 2 and b, a quarter of them at each end.
  const Summary two = Summarize(std::vector<double>{0.2, 0.6});
  EXPECT_DOUBLE_EQ(two.ci_lo, 0.2);
  EXPECT_DOUBLE_EQ(two.ci_hi, 0.6);
  // Paired differences of fractions stay within [-1, 1].
  const Summary d = Summarize(std::vector<double>{-1.0, 1.0, 1.0, -1.0});
  EXPECT_GE(d.ci_lo, -1.0);
  EXPECT_LE(d.ci_hi, 1.0);
}

TEST(StatisticsTest, MeanIntervalTextAndPairedVerdicts) {
  EXPECT_EQ(FormatMeanInterval(Summarize(std::vector<double>{0.2, 0.6})), "0.400 [0.200, 0.600]");
  EXPECT_EQ(FormatMeanInterval(Summarize(std::vector<double>{0.7})), "0.700 (n = 1, no interval)");
  EXPECT_EQ(FormatMeanInterval(Summarize({})), "–");
  EXPECT_EQ(FormatMeanInterval(Summarize(std::vector<double>{0.1, 0.3}), 2, true),
            "+0.20 [+0.10, +0.30]");
  EXPECT_EQ(PairedVerdict(Summarize(std::vector<double>{0.1, 0.3, 0.2})), "ahead");
  EXPECT_EQ(PairedVerdict(Summarize(std::vector<double>{-0.1, -0.3, -0.2})), "behind");
  EXPECT_EQ(PairedVerdict(Summarize(std::vector<double>{-0.1, 0.3, 0.2})), "tied");
  EXPECT_EQ(PairedVerdict(Summarize(std::vector<double>{0.5})), "n/a");
}

TEST(StatisticsTest, FiveSeedsOfF1) {
  const std::vector<double> f1 = {0.61, 0.58, 0.66, 0.63, 0.57};
  const Summary s = Summarize(f1);
  EXPECT_NEAR(s.mean, 0.61, 1e-12);
  // Deviations 0, -0.03, 0.05, 0.02, -0.04: squares sum 0.0054, variance 0.00135.
  EXPECT_NEAR(s.sd, std::sqrt(0.00135), 1e-12);
  EXPECT_GE(s.ci_lo, 0.57);
  EXPECT_LE(s.ci_hi, 0.66);
  EXPECT_LT(s.ci_lo, 0.61);
  EXPECT_GT(s.ci_hi, 0.61);
}

TEST(StatisticsTest, LargeSampleUsesNormalQuantile) {
  std::vector<double> v;
  for (int i = 0; i < 40; ++i) v.push_back(i % 2 == 0 ? 1.0 : 3.0);
  const Summary s = Summarize(v);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_NEAR(s.sd, std::sqrt(40.0 / 39.0), 1e-12);
  // At n = 40 the bootstrap agrees with the normal theory: 2 +- 1.96 * 1.0 / sqrt(40) = 2 +- 0.31.
  EXPECT_NEAR(s.ci_lo, 2.0 - 1.96 / std::sqrt(40.0), 0.05);
  EXPECT_NEAR(s.ci_hi, 2.0 + 1.96 / std::sqrt(40.0), 0.05);
}

TEST(StatisticsTest, EdgeCases) {
  const Summary empty = Summarize({});
  EXPECT_EQ(empty.n, 0u);
  EXPECT_TRUE(std::isnan(empty.mean));
  EXPECT_TRUE(std::isnan(empty.sd));
  EXPECT_TRUE(std::isnan(empty.ci_lo));
  EXPECT_FALSE(empty.has_interval());

  const std::vector<double> one = {0.7};
  const Summary single = Summarize(one);
  EXPECT_EQ(single.n, 1u);
  EXPECT_DOUBLE_EQ(single.mean, 0.7);
  EXPECT_TRUE(std::isnan(single.sd));
  EXPECT_TRUE(std::isnan(single.ci_lo));
  EXPECT_TRUE(std::isnan(single.ci_hi));

  const std::vector<double> with_nan = {1.0, kNaN, 3.0, std::numeric_limits<double>::infinity()};
  const Summary s = Summarize(with_nan);
  EXPECT_EQ(s.n, 2u);
  EXPECT_EQ(s.skipped, 2u);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_NEAR(s.sd, std::sqrt(2.0), 1e-12);
  EXPECT_DOUBLE_EQ(s.ci_lo, 1.0);
  EXPECT_DOUBLE_EQ(s.ci_hi, 3.0);

  const std::vector<double> constant = {0.25, 0.25, 0.25};
  const Summary c = Summarize(constant);
  EXPECT_DOUBLE_EQ(c.sd, 0.0);
  EXPECT_DOUBLE_EQ(c.ci_lo, 0.25);
  EXPECT_DOUBLE_EQ(c.ci_hi, 0.25);
}

}  // namespace
TEST(StatisticsTest, MedianOfOddEvenAndNonFiniteSamples) {
  EXPECT_DOUBLE_EQ(Median(std::vector<double>{3.0, 1.0, 2.0}), 2.0);
  EXPECT_DOUBLE_EQ(Median(std::vector<double>{4.0, 1.0, 3.0, 2.0}), 2.5);
  const double nan = std::nan("");
  EXPECT_DOUBLE_EQ(Median(std::vector<double>{nan, 5.0, INFINITY, -1.0}), 2.0);
  EXPECT_TRUE(std::isnan(Median(std::vector<double>{})));
  EXPECT_TRUE(std::isnan(Median(std::vector<double>{nan})));
}

TEST(SpearmanTest, RanksWithTiesAndDegenerateSamples) {
  const std::vector<double> a = {1.0, 2.0, 3.0, 4.0, 5.0};
  EXPECT_DOUBLE_EQ(SpearmanRankCorrelation(a, std::vector<double>{10, 20, 30, 40, 50}), 1.0);
  EXPECT_DOUBLE_EQ(SpearmanRankCorrelation(a, std::vector<double>{5, 4, 3, 2, 1}), -1.0);
  // Monotone but not linear: ranks only.
  EXPECT_DOUBLE_EQ(SpearmanRankCorrelation(a, std::vector<double>{1, 4, 9, 16, 1000}), 1.0);
  // By hand: b's ranks 2, 1, 4, 3, 5 against 1..5: 1 - 6 * 4 / (5 * 24) = 0.8.
  EXPECT_NEAR(SpearmanRankCorrelation(a, std::vector<double>{2, 1, 4, 3, 5}), 0.8, 1e-12);
  // Ties share the mean rank: b = 1, 1, 2 ranks 1.5, 1.5, 3; Pearson with 1, 2, 3 is sqrt(3)/2.
  EXPECT_NEAR(SpearmanRankCorrelation(std::vector<double>{1, 2, 3}, std::vector<double>{1, 1, 2}),
              std::sqrt(3.0) / 2.0, 1e-12);
  EXPECT_TRUE(std::isnan(SpearmanRankCorrelation(a, std::vector<double>{7, 7, 7, 7, 7})));
  EXPECT_TRUE(std::isnan(SpearmanRankCorrelation(a, std::vector<double>{1, 2})));
  EXPECT_TRUE(std::isnan(SpearmanRankCorrelation(std::vector<double>{1}, std::vector<double>{1})));
}

}  // namespace avp::eval
