// The pods' depth filter before fusion (server/fusion/depth_filter.h).
#include "server/fusion/depth_filter.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace holo {
namespace {

// A fronto-parallel plane at `mm` with Gaussian noise σ (mm), w × h.
ImageDepth16 NoisyPlane(int w, int h, double mm, double sigma, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, sigma);
  ImageDepth16 d(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) d.at(x, y) = static_cast<uint16_t>(std::lround(mm + (sigma > 0 ? n(rng) : 0.0)));
  return d;
}

double RmsAbout(const ImageDepth16& d, double mm, int margin) {
  double s = 0;
  int n = 0;
  for (int y = margin; y < d.height() - margin; ++y)
    for (int x = margin; x < d.width() - margin; ++x) {
      s += (d.at(x, y) - mm) * (d.at(x, y) - mm);
      ++n;
    }
  return std::sqrt(s / n);
}

std::unique_ptr<DepthFilter> Make(int radius = 2) {
  DepthFilterOptions o;
  o.radius = radius;
  auto f = DepthFilter::Create(o);
  EXPECT_TRUE(f.ok()) << f.status().ToString();
  return f.ok() ? std::move(*f) : nullptr;
}

// The studio's noise at 2.5 m (σ = 3 mm · 2.5² ≈ 19 mm): a 5 × 5 window
// averages 25 samples, so σ falls about five-fold.
TEST(DepthFilter, ReducesNoiseOnAFlatSurface) {
  ImageDepth16 d = NoisyPlane(80, 60, 2500, 18.75, 7);
  const double before = RmsAbout(d, 2500, 2);
  auto f = Make();
  ASSERT_TRUE(f->Apply(&d, ImageGray8()).ok());
  const double after = RmsAbout(d, 2500, 2);
  EXPECT_GT(before, 17.0);
  EXPECT_LT(after, before / 3.5) << before << " → " << after;
}

// Two surfaces 30 cm apart (an arm in front of the body): neither bleeds
// into the other, even in the pixels right at the edge.
TEST(DepthFilter, KeepsDepthEdges) {
  ImageDepth16 d(40, 20);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 40; ++x) d.at(x, y) = x < 20 ? 2000 : 2300;
  const ImageDepth16 before = d;
  auto f = Make(3);
  ASSERT_TRUE(f->Apply(&d, ImageGray8()).ok());
  EXPECT_EQ(d, before);
}

// Background pixels (mask 0) close in depth to the person — a foot on the
// floor — neither change nor pull the person's depth towards theirs.
TEST(DepthFilter, UsesOnlyTheMaskedPixels) {
  ImageDepth16 d(30, 30);
  ImageGray8 mask(30, 30);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 30; ++x) {
      const bool person = x >= 10 && x < 20 && y >= 10 && y < 20;
      d.at(x, y) = person ? 2000 : 2020;
      mask.at(x, y) = person ? 255 : 0;
    }
  d.at(0, 0) = 0;  // a dropout stays one
  const ImageDepth16 before = d;
  auto f = Make();
  ASSERT_TRUE(f->Apply(&d, mask).ok());
  EXPECT_EQ(d, before);
}

// A hole in the person's depth (a dropout) stays a hole and does not drag
// its neighbours towards zero.
TEST(DepthFilter, DropoutsStayAndDoNotCount) {
  ImageDepth16 d(20, 20, 1500);
  d.at(10, 10) = 0;
  const ImageDepth16 before = d;
  auto f = Make();
  ASSERT_TRUE(f->Apply(&d, ImageGray8()).ok());
  EXPECT_EQ(d, before);
}

// A linear ramp (a tilted plane) is kept in the interior: the window's mean
// of a linear function is its value at the centre.
TEST(DepthFilter, KeepsATiltedPlane) {
  ImageDepth16 d(40, 40);
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 40; ++x) d.at(x, y) = static_cast<uint16_t>(2000 + 4 * x + 2 * y);
  const ImageDepth16 before = d;
  auto f = Make();
  ASSERT_TRUE(f->Apply(&d, ImageGray8()).ok());
  for (int y = 2; y < 38; ++y)
    for (int x = 2; x < 38; ++x) ASSERT_EQ(d.at(x, y), before.at(x, y)) << x << "," << y;
}

TEST(DepthFilter, FrameSetMatchesOneImageAtATimeOnAnyThreadCount) {
  RgbdFrameSet frames;
  for (int p = 0; p < 5; ++p) {
    RgbdFrame f;
    f.pod_id = p;
    f.depth = NoisyPlane(64, 48, 1800 + 100 * p, 10, static_cast<uint32_t>(p));
    f.mask = ImageGray8(64, 48, 0);
    for (int y = 8; y < 40; ++y)
      for (int x = 16 + p; x < 50; ++x) f.mask.at(x, y) = 255;
    frames.frames.push_back(f);
  }
  RgbdFrameSet one = frames;
  auto single = Make();
  for (auto& f : one.frames) ASSERT_TRUE(single->Apply(&f.depth, f.mask).ok());
  DepthFilterOptions o;
  o.threads = 3;
  auto pooled = DepthFilter::Create(o);
  ASSERT_TRUE(pooled.ok());
  ASSERT_TRUE((*pooled)->Apply(&frames).ok());
  for (size_t p = 0; p < frames.frames.size(); ++p) EXPECT_EQ(frames.frames[p].depth, one.frames[p].depth) << p;
  EXPECT_NE(frames.frames[0].depth, NoisyPlane(64, 48, 1800, 10, 0)) << "the filter changed nothing";
}

TEST(DepthFilter, RefusesBadOptionsAndMismatchedMasksWithoutTouchingTheFrames) {
  DepthFilterOptions o;
  o.radius = 9;
  auto bad = DepthFilter::Create(o);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("radius"), std::string::npos) << bad.status().ToString();
  o = DepthFilterOptions{};
  o.range_sigmas = 0;
  EXPECT_FALSE(DepthFilter::Create(o).ok());
  o = DepthFilterOptions{};
  o.sigma_at_1m_mm = std::nanf("");
  EXPECT_FALSE(DepthFilter::Create(o).ok());

  RgbdFrameSet frames;
  for (int p = 0; p < 2; ++p) {
    RgbdFrame f;
    f.pod_id = p;
    f.depth = NoisyPlane(32, 24, 2000, 15, static_cast<uint32_t>(p));
    frames.frames.push_back(f);
  }
  frames.frames[1].mask = ImageGray8(16, 12, 255);
  const RgbdFrameSet before = frames;
  auto f = Make();
  Status s = f->Apply(&frames);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("pod 1"), std::string::npos) << s.ToString();
  for (size_t p = 0; p < frames.frames.size(); ++p) EXPECT_EQ(frames.frames[p].depth, before.frames[p].depth);
}

TEST(DepthFilter, RadiusZeroChangesNothing) {
  ImageDepth16 d = NoisyPlane(32, 24, 2000, 15, 3);
  const ImageDepth16 before = d;
  auto f = Make(0);
  ASSERT_TRUE(f->Apply(&d, ImageGray8()).ok());
  EXPECT_EQ(d, before);
}

}  // namespace
}  // namespace holo
