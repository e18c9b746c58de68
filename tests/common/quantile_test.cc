// Quantile and InterpolatedQuantile: the ranks every statistic and figure
// relies on (a p50 of an even count, the ends, no values); AppendRecent: the
// bounded history those statistics are taken over.
#include <vector>

#include <gtest/gtest.h>

#include "common/quantile.h"
#include "common/recent.h"

namespace holo {
namespace {

TEST(Quantile, NearestRankRoundsTheRank) {
  const std::vector<double> v = {50, 10, 40, 20, 30};  // sorted: 10 20 30 40 50
  EXPECT_EQ(Quantile(v, 0.0), 10);
  EXPECT_EQ(Quantile(v, 0.5), 30);
  EXPECT_EQ(Quantile(v, 0.6), 30);   // rank 2.4 → 2
  EXPECT_EQ(Quantile(v, 0.65), 40);  // rank 2.6 → 3
  EXPECT_EQ(Quantile(v, 0.99), 50);
  EXPECT_EQ(Quantile(v, 1.0), 50);
  // The median of an even count is the upper middle value.
  EXPECT_EQ(Quantile(std::vector<double>{4, 1, 3, 2}, 0.5), 3);
  EXPECT_EQ(Quantile(std::vector<double>{7}, 0.99), 7);
}

TEST(Quantile, FloatSamplesAndNoSamples) {
  EXPECT_FLOAT_EQ(Quantile(std::vector<float>{-1.5f, 2.5f, 0.5f}, 0.5), 0.5);
  EXPECT_EQ(Quantile(std::vector<double>{}, 0.5), 0.0);
  EXPECT_EQ(Quantile(std::vector<float>{}, 0.99), 0.0);
}

TEST(InterpolatedQuantile, InterpolatesBetweenNeighbouringRanks) {
  const std::vector<double> v = {40, 10, 30, 20};  // sorted: 10 20 30 40
  EXPECT_DOUBLE_EQ(InterpolatedQuantile(v, 0.0), 10);
  EXPECT_DOUBLE_EQ(InterpolatedQuantile(v, 0.5), 25);   // rank 1.5
  EXPECT_DOUBLE_EQ(InterpolatedQuantile(v, 0.99), 39.7);  // rank 2.97
  EXPECT_DOUBLE_EQ(InterpolatedQuantile(v, 1.0), 40);
  EXPECT_DOUBLE_EQ(InterpolatedQuantile({5}, 0.99), 5);
  EXPECT_EQ(InterpolatedQuantile({}, 0.5), 0.0);
  EXPECT_EQ(InterpolatedQuantile({}, 0.5, -1.0), -1.0);
}

TEST(AppendRecent, KeepsTheNewestInOrderWithinTwiceTheBound) {
  std::vector<int> h;
  for (int i = 0; i < 10; ++i) AppendRecent(&h, i, 3);
  // Dropped the oldest 3 at 6 held and again at 6 held: 6..9 remain.
  EXPECT_EQ(h, (std::vector<int>{6, 7, 8, 9}));
  for (int i = 10; i < 1000; ++i) {
    AppendRecent(&h, i, 3);
    ASSERT_GE(h.size(), 3u);
    ASSERT_LE(h.size(), 6u);
    ASSERT_EQ(h.back(), i);
  }
  std::vector<int> all;
  for (int i = 0; i < 100; ++i) AppendRecent(&all, i, 0);  // 0: keep everything
  EXPECT_EQ(all.size(), 100u);
}

}  // namespace
}  // namespace holo
