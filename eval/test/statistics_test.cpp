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
  EXPECT_NEAR(s.ci95, 2.364624 * std::sqrt(32.0 / 7.0) / std::sqrt(8.0), 1e-6);
}

TEST(StatisticsTest, FiveSeedsOfF1) {
  const std::vector<double> f1 = {0.61, 0.58, 0.66, 0.63, 0.57};
  const Summary s = Summarize(f1);
  EXPECT_NEAR(s.mean, 0.61, 1e-12);
  // Deviations 0, -0.03, 0.05, 0.02, -0.04: squares sum 0.0054, variance 0.00135.
  EXPECT_NEAR(s.sd, std::sqrt(0.00135), 1e-12);
  EXPECT_NEAR(s.ci95, 2.776445 * std::sqrt(0.00135 / 5.0), 1e-7);
}

TEST(StatisticsTest, LargeSampleUsesNormalQuantile) {
  std::vector<double> v;
  for (int i = 0; i < 40; ++i) v.push_back(i % 2 == 0 ? 1.0 : 3.0);
  const Summary s = Summarize(v);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_NEAR(s.sd, std::sqrt(40.0 / 39.0), 1e-12);
  EXPECT_NEAR(s.ci95, 1.96 * s.sd / std::sqrt(40.0), 1e-12);
}

TEST(StatisticsTest, EdgeCases) {
  const Summary empty = Summarize({});
  EXPECT_EQ(empty.n, 0u);
  EXPECT_TRUE(std::isnan(empty.mean));
  EXPECT_TRUE(std::isnan(empty.sd));
  EXPECT_TRUE(std::isnan(empty.ci95));

  const std::vector<double> one = {0.7};
  const Summary single = Summarize(one);
  EXPECT_EQ(single.n, 1u);
  EXPECT_DOUBLE_EQ(single.mean, 0.7);
  EXPECT_TRUE(std::isnan(single.sd));
  EXPECT_TRUE(std::isnan(single.ci95));

  const std::vector<double> with_nan = {1.0, kNaN, 3.0, std::numeric_limits<double>::infinity()};
  const Summary s = Summarize(with_nan);
  EXPECT_EQ(s.n, 2u);
  EXPECT_EQ(s.skipped, 2u);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_NEAR(s.sd, std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(s.ci95, 12.706205 * std::sqrt(2.0) / std::sqrt(2.0), 1e-6);

  const std::vector<double> constant = {0.25, 0.25, 0.25};
  const Summary c = Summarize(constant);
  EXPECT_DOUBLE_EQ(c.sd, 0.0);
  EXPECT_DOUBLE_EQ(c.ci95, 0.0);
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
