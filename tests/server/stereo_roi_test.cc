// PatchMatch restricted to a region of the left image, and the policy that
// chooses the region (server/stereo/stereo_roi.h): the region's result
// against a full run, nothing outside it, regions at the border and empty,
// and a person entering the view found within the stated number of frames.
#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "common/rig.h"
#include "server/stereo/patchmatch.h"
#include "server/stereo/stereo_depth.h"
#include "server/stereo/stereo_roi.h"
#include "studio/stereo_render.h"
#include "studio/studio.h"
#include "slanted_plane_pair.h"

namespace holo {
namespace {

// The slanted-plane pair of slanted_plane_pair.h, into separate images.
void SlantedPlane(int W, int H, float a, float b, float c, ImageGray8* left, ImageGray8* right, ImageFloat* truth) {
  SyntheticPair p = holo::SlantedPlane(W, H, a, b, c);
  *left = std::move(p.left);
  *right = std::move(p.right);
  *truth = std::move(p.truth);
}

int CountNonZeroOutside(const ImageFloat& d, const RowSpans& s) {
  int n = 0;
  for (int y = 0; y < d.height(); ++y)
    for (int x = 0; x < d.width(); ++x) n += !s.Contains(x, y) && d.at(x, y) != 0.0f;
  return n;
}

int CountNonZeroOutside(const ImageFloat& d, const ImageRect& r) {
  return CountNonZeroOutside(d, RowSpans::FromRect(r, d.width(), d.height()));
}

// Errors against the truth over the spans' pixels: (valid share, median, p90).
std::array<double, 3> SpanErrors(const ImageFloat& d, const ImageFloat& truth, const RowSpans& s) {
  std::vector<float> err;
  int total = 0;
  for (int y = 0; y < d.height(); ++y)
    for (int x = s.x0[static_cast<size_t>(y)]; x < s.x1[static_cast<size_t>(y)]; ++x) {
      ++total;
      if (d.at(x, y) > 0.0f) err.push_back(std::abs(d.at(x, y) - truth.at(x, y)));
    }
  if (err.empty()) return {0.0, 1e9, 1e9};
  std::sort(err.begin(), err.end());
  return {static_cast<double>(err.size()) / std::max(total, 1), err[err.size() / 2], err[err.size() * 9 / 10]};
}

// The slanted-plane tests' matcher options: disparities 0-40, 2 threads.
PatchMatchOptions PlaneOptions(bool force_scalar = false) {
  PatchMatchOptions o;
  o.min_disparity = 0;
  o.max_disparity = 40;
  o.threads = 2;
  o.force_scalar = force_scalar;
  return o;
}

TEST(PatchMatchRegionTest, WholeImageRegionEqualsFullRunBitForBit) {
  ImageGray8 l, r;
  ImageFloat truth, a, b;
  SlantedPlane(96, 64, 0.03f, 0.05f, 10.0f, &l, &r, &truth);
  PatchMatchOptions o;
  o.min_disparity = 2;
  o.max_disparity = 24;
  o.threads = 2;
  PatchMatchStereo pm(o);
  ASSERT_TRUE(pm.Compute(l, r, &a).ok());
  const ImageFloat right_full = pm.right_disparity();
  // A rectangle reaching beyond the image is clipped to it.
  ASSERT_TRUE(pm.Compute(l, r, ImageRect{-5, -3, 200, 100}, &b).ok());
  EXPECT_TRUE(a == b);
  EXPECT_TRUE(right_full == pm.right_disparity());
}

// On the slanted plane, a region in the middle and one at the image's corner
// recover the plane as the full run does (median < 0.1 px, 90th percentile
// < 0.3 px), on the AVX2 and the scalar path, and leave every pixel outside
// at 0; results do not depend on the thread count.
void ExpectRegionRecoversPlane(bool force_scalar) {
  const int W = 160, H = 120;
  ImageGray8 l, r;
  ImageFloat truth;
  SlantedPlane(W, H, 0.06f, -0.04f, 14.0f, &l, &r, &truth);  // d ~9.2 .. ~23.6 px
  PatchMatchStereo pm(PlaneOptions(force_scalar));
  for (const ImageRect& region : {ImageRect{60, 30, 110, 90}, ImageRect{110, 80, 160, 120}, ImageRect{40, 0, 44, 120}}) {
    ImageFloat d;
    ASSERT_TRUE(pm.Compute(l, r, region, &d).ok());
    EXPECT_EQ(CountNonZeroOutside(d, region), 0);
    EXPECT_EQ(CountNonZeroOutside(pm.right_disparity(), pm.RightRegion(region, W, H)), 0);
    const auto e = SpanErrors(d, truth, RowSpans::FromRect(region, W, H));
    EXPECT_GT(e[0], 0.8) << "region " << region.x0 << "," << region.y0 << ": valid share";
    EXPECT_LT(e[1], 0.1);
    EXPECT_LT(e[2], 0.3);
  }
}
TEST(PatchMatchRegionTest, RegionRecoversSlantedPlane) { ExpectRegionRecoversPlane(false); }
TEST(PatchMatchRegionTest, ScalarPathRegionRecoversSlantedPlane) { ExpectRegionRecoversPlane(true); }

// PatchMatchOptions::temporal: a region of the next frame starts from the
// last frame's planes and one lighter iteration recovers the moved plane as
// well as the full algorithm; the whole image and a region that left the
// last one run the full algorithm (a fresh matcher's result, bit for bit).
// The whole view moves here: with temporal_still on its pixels are matched
// again, none left alone with an old plane (its noise level rises from 0).
TEST(PatchMatchTemporalTest, ARegionStartsFromTheLastPlanesAndFollowsTheMotion) {
  const int W = 160, H = 120;
  const PatchMatchOptions o = PlaneOptions();
  PatchMatchOptions t = o;
  t.temporal = true;
  t.temporal_still = 1.0f;
  PatchMatchStereo pm(t);
  const ImageRect region{50, 20, 130, 100};
  ImageGray8 l, r;
  ImageFloat truth, d;
  // The plane tilts and comes nearer frame by frame: ten frames in the
  // region, each from the last one's planes.
  for (int f = 0; f < 10; ++f) {
    SlantedPlane(W, H, 0.06f + 0.002f * f, -0.04f, 14.0f + 0.3f * f, &l, &r, &truth);
    ASSERT_TRUE(pm.Compute(l, r, f == 0 ? ImageRect::Full(W, H) : region, &d).ok());
    EXPECT_EQ(pm.last_was_temporal(), f > 0) << "frame " << f;
  }
  EXPECT_EQ(CountNonZeroOutside(d, region), 0);
  const auto e = SpanErrors(d, truth, RowSpans::FromRect(region, W, H));
  EXPECT_GT(e[0], 0.9) << "valid share";
  EXPECT_LT(e[1], 0.1);
  EXPECT_LT(e[2], 0.3);

  // The whole image, and a region mostly outside the last one: the full
  // algorithm, as a fresh matcher gives it.
  PatchMatchStereo fresh(o);
  ImageFloat a, b;
  ASSERT_TRUE(pm.Compute(l, r, ImageRect::Full(W, H), &a).ok());
  EXPECT_FALSE(pm.last_was_temporal());
  ASSERT_TRUE(fresh.Compute(l, r, ImageRect::Full(W, H), &b).ok());
  EXPECT_TRUE(a == b);
  ASSERT_TRUE(pm.Compute(l, r, region, &a).ok());  // from the whole image's planes
  EXPECT_TRUE(pm.last_was_temporal());
  const ImageRect elsewhere{0, 0, 60, 50};         // overlaps the last region by 10×30 of 60×50
  ASSERT_TRUE(pm.Compute(l, r, elsewhere, &a).ok());
  EXPECT_FALSE(pm.last_was_temporal());
  ASSERT_TRUE(fresh.Compute(l, r, elsewhere, &b).ok());
  EXPECT_TRUE(a == b);
}

// PatchMatchOptions::temporal_still. A still textured plane seen with
// sensor noise (±3 grey levels, new every frame); inside the region the
// plane later tilts and comes nearer while the rest of the view stays still
// (the region holds what moves; the noise level comes from outside it).
// With the option, on still frames most of the region keeps its planes:
// the disparities are the last frame's, bit for bit (without it the
// refinement moves most of them); once the plane moves, the pixels are
// matched again and the moved plane is recovered as without the option.
void AddNoise(ImageGray8* img, uint64_t seed) {
  for (int y = 0; y < img->height(); ++y)
    for (int x = 0; x < img->width(); ++x) {
      uint64_t h = (seed * 1000003ULL + static_cast<uint64_t>(y)) * 0x9E3779B97F4A7C15ULL + static_cast<uint64_t>(x);
      h ^= h >> 31;
      h *= 0xBF58476D1CE4E5B9ULL;
      h ^= h >> 29;
      const int n = static_cast<int>(h % 7) - 3;
      img->at(x, y) = static_cast<uint8_t>(std::clamp(img->at(x, y) + n, 0, 255));
    }
}

TEST(PatchMatchTemporalTest, StillPixelsKeepTheirPlanesUntilTheImagesChange) {
  const int W = 160, H = 120;
  const ImageRect region{50, 20, 130, 100};
  for (const float still : {0.0f, 1.1f}) {
    PatchMatchOptions o = PlaneOptions();
    o.temporal = true;
    o.temporal_still = still;
    PatchMatchStereo pm(o);
    // Frame f: the still plane, and inside the region (the right view's
    // columns its pixels match in) the moving one.
    auto frame = [&](int f, int moved, ImageGray8* l, ImageGray8* r, ImageFloat* truth) {
      const SyntheticPair s = holo::SlantedPlane(W, H, 0.06f, -0.04f, 14.0f);
      const SyntheticPair m = holo::SlantedPlane(W, H, 0.06f + 0.002f * moved, -0.04f, 14.0f + 0.3f * moved);
      *l = s.left;  // the texture is the left view's: the same for both planes
      *r = s.right;
      *truth = m.truth;
      for (int y = region.y0; y < region.y1; ++y)
        for (int x = region.x0 - 30; x < region.x1; ++x) r->at(x, y) = m.right.at(x, y);
      AddNoise(l, static_cast<uint64_t>(2 * f));
      AddNoise(r, static_cast<uint64_t>(2 * f + 1));
    };
    ImageGray8 l, r;
    ImageFloat truth, d, last;
    frame(0, 0, &l, &r, &truth);
    ASSERT_TRUE(pm.Compute(l, r, ImageRect::Full(W, H), &last).ok());
    for (int f = 1; f <= 14; ++f) {  // still (the noise level is learnt in ~10 frames)
      frame(f, 0, &l, &r, &truth);
      ASSERT_TRUE(pm.Compute(l, r, region, &d).ok());
      ASSERT_TRUE(pm.last_was_temporal());
      if (f < 12) {
        last = d;
        continue;
      }
      int same = 0;
      for (int y = region.y0; y < region.y1; ++y)
        for (int x = region.x0; x < region.x1; ++x) same += d.at(x, y) == last.at(x, y);
      if (still > 0.0f) {
        EXPECT_GT(same, static_cast<int>(region.area()) * 6 / 10) << "frame " << f << ": planes kept";
      } else {
        EXPECT_LT(same, static_cast<int>(region.area()) * 4 / 10) << "frame " << f << ": planes matched again";
      }
      last = d;
    }
    for (int f = 15; f <= 23; ++f) {  // the plane moves inside the region
      frame(f, f - 14, &l, &r, &truth);
      ASSERT_TRUE(pm.Compute(l, r, region, &d).ok());
    }
    // Inside the region, away from the seam between the two planes.
    const auto e = SpanErrors(d, truth, RowSpans::FromRect(ImageRect{60, 25, 125, 95}, W, H));
    EXPECT_GT(e[0], 0.9) << "still " << still << ": valid share";
    EXPECT_LT(e[1], 0.1) << "still " << still;
    EXPECT_LT(e[2], 0.3) << "still " << still;
  }
}

TEST(PatchMatchTemporalTest, OptionsAreChecked) {
  PatchMatchOptions o;
  o.temporal_min_overlap = 0.0f;
  EXPECT_NE(o.Check().message().find("temporal_min_overlap"), std::string::npos);
  o = PatchMatchOptions{};
  o.temporal_iterations = 0;
  EXPECT_NE(o.Check().message().find("temporal_iterations"), std::string::npos);
  o = PatchMatchOptions{};
  o.temporal_refine_start = 21;
  EXPECT_NE(o.Check().message().find("temporal_refine_start"), std::string::npos);
  o = PatchMatchOptions{};
  o.temporal_refine_per_sweep = 9;
  EXPECT_NE(o.Check().message().find("temporal_refine_per_sweep"), std::string::npos);
  o = PatchMatchOptions{};
  o.temporal_still = -1.0f;
  EXPECT_NE(o.Check().message().find("temporal_still"), std::string::npos);
}

TEST(PatchMatchRegionTest, RegionResultDoesNotDependOnThreadCount) {
  ImageGray8 l, r;
  ImageFloat truth, a, b;
  SlantedPlane(128, 64, 0.0f, 0.05f, 10.0f, &l, &r, &truth);
  PatchMatchOptions o;
  o.max_disparity = 24;
  o.threads = 1;
  PatchMatchStereo one(o);
  o.threads = 3;
  PatchMatchStereo three(o);
  const ImageRect region{37, 9, 101, 50};
  ASSERT_TRUE(one.Compute(l, r, region, &a).ok());
  ASSERT_TRUE(three.Compute(l, r, region, &b).ok());
  EXPECT_TRUE(a == b);
}

TEST(PatchMatchRegionTest, EmptyAndTinyRegions) {
  ImageGray8 l, r;
  ImageFloat truth, d;
  SlantedPlane(64, 32, 0.0f, 0.0f, 8.0f, &l, &r, &truth);
  PatchMatchOptions o;
  o.max_disparity = 16;
  o.threads = 2;
  PatchMatchStereo pm(o);
  ASSERT_TRUE(pm.Compute(l, r, &d).ok());
  // Empty (and entirely outside the image): all 0, no error.
  for (const ImageRect& e : {ImageRect{}, ImageRect{10, 10, 10, 20}, ImageRect{70, 0, 90, 10}, ImageRect{5, 5, 3, 9}}) {
    ASSERT_TRUE(pm.Compute(l, r, e, &d).ok());
    EXPECT_EQ(d.width(), 64);
    EXPECT_EQ(CountNonZeroOutside(d, ImageRect{}), 0);
    EXPECT_EQ(CountNonZeroOutside(pm.right_disparity(), ImageRect{}), 0);
  }
  // One pixel, and one row at the image's last row.
  for (const ImageRect& t : {ImageRect{40, 16, 41, 17}, ImageRect{0, 31, 64, 32}}) {
    ASSERT_TRUE(pm.Compute(l, r, t, &d).ok());
    EXPECT_EQ(CountNonZeroOutside(d, t), 0);
  }
  EXPECT_NEAR(d.at(40, 31), 8.0f, 0.5f);
  // Row spans of the wrong height are refused; spans beyond the image are
  // clipped to it.
  const Status s = pm.Compute(l, r, RowSpans::FromRect(ImageRect{0, 0, 64, 31}, 64, 31), 16.0f, &d);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("row spans: 31 rows for a 32-row image"), std::string::npos) << s.message();
  RowSpans wide = RowSpans::FromRect(ImageRect{0, 0, 64, 32}, 64, 32);
  wide.x0[3] = -10;
  wide.x1[3] = 100;
  ASSERT_TRUE(pm.Compute(l, r, wide, 16.0f, &d).ok());
  EXPECT_EQ(d.width(), 64);
}

// ---- Regions as row spans ---------------------------------------------------

// A disc of radius r around (cx, cy), and optionally a second one, as row
// spans of a width × height image (rows between them empty).
RowSpans Discs(int width, int height, std::vector<std::array<int, 3>> discs) {
  RowSpans s;
  s.x0.assign(static_cast<size_t>(height), 0);
  s.x1.assign(static_cast<size_t>(height), 0);
  for (const auto& [cx, cy, r] : discs)
    for (int y = std::max(0, cy - r); y <= std::min(height - 1, cy + r); ++y) {
      const int h = static_cast<int>(std::sqrt(static_cast<double>(r * r - (y - cy) * (y - cy))));
      s.x0[static_cast<size_t>(y)] = std::max(0, cx - h);
      s.x1[static_cast<size_t>(y)] = std::min(width, cx + h + 1);
    }
  return s;
}

// The right view's spans for left spans: each widened to the left by the
// largest disparity.
RowSpans RightSpans(const RowSpans& left, float max_disparity) {
  RowSpans r = left;
  for (int y = 0; y < r.rows(); ++y)
    if (r.x1[static_cast<size_t>(y)] > r.x0[static_cast<size_t>(y)])
      r.x0[static_cast<size_t>(y)] = std::max(0, r.x0[static_cast<size_t>(y)] - static_cast<int>(std::ceil(max_disparity)));
  return r;
}

// Two discs with empty rows between them, one at the image's edge: the
// slanted plane is recovered there as in a rectangle (median < 0.1 px, 90th
// percentile < 0.3 px), on the AVX2 and the scalar path, nothing outside
// the spans in either view; the result does not depend on the thread count.
void ExpectSpansRecoverPlane(bool force_scalar) {
  const int W = 160, H = 120;
  ImageGray8 l, r;
  ImageFloat truth;
  SlantedPlane(W, H, 0.06f, -0.04f, 14.0f, &l, &r, &truth);
  PatchMatchOptions o = PlaneOptions(force_scalar);
  PatchMatchStereo pm(o);
  const RowSpans spans = Discs(W, H, {{{70, 35, 25}}, {{150, 95, 20}}});
  ASSERT_GT(spans.x1[58], 0);  // the first disc reaches row 60, the second starts at 75
  ASSERT_EQ(spans.x1[68], 0);
  ImageFloat d;
  ASSERT_TRUE(pm.Compute(l, r, spans, o.max_disparity, &d).ok());
  EXPECT_EQ(CountNonZeroOutside(d, spans), 0);
  EXPECT_EQ(CountNonZeroOutside(pm.right_disparity(), RightSpans(spans, o.max_disparity)), 0);
  const auto e = SpanErrors(d, truth, spans);
  EXPECT_GT(e[0], 0.8) << "valid share";
  EXPECT_LT(e[1], 0.1);
  EXPECT_LT(e[2], 0.3);
  o.threads = 3;
  PatchMatchStereo three(o);
  ImageFloat d3;
  ASSERT_TRUE(three.Compute(l, r, spans, o.max_disparity, &d3).ok());
  EXPECT_TRUE(d == d3);
}
TEST(PatchMatchSpansTest, SpansRecoverSlantedPlane) { ExpectSpansRecoverPlane(false); }
TEST(PatchMatchSpansTest, ScalarPathSpansRecoverSlantedPlane) { ExpectSpansRecoverPlane(true); }

// Frames in sequence (PatchMatchOptions::temporal): a disc that moves a pixel
// per frame is matched from the last frame's planes, and pixels new to the
// spans (outside the last ones) start from their row's nearest old plane.
TEST(PatchMatchSpansTest, TemporalSpansFollowAMovingDisc) {
  const int W = 160, H = 120;
  PatchMatchOptions o = PlaneOptions();
  o.temporal = true;
  o.temporal_still = 1.0f;  // the whole view moves: nothing may be left alone
  PatchMatchStereo pm(o);
  ImageGray8 l, r;
  ImageFloat truth, d;
  RowSpans spans;
  for (int f = 0; f < 10; ++f) {
    SlantedPlane(W, H, 0.06f + 0.002f * f, -0.04f, 14.0f + 0.3f * f, &l, &r, &truth);
    spans = f == 0 ? RowSpans::FromRect(ImageRect::Full(W, H), W, H) : Discs(W, H, {{{60 + 2 * f, 60 + f, 30}}});
    ASSERT_TRUE(pm.Compute(l, r, spans, o.max_disparity, &d).ok());
    EXPECT_EQ(pm.last_was_temporal(), f > 0) << "frame " << f;
  }
  EXPECT_EQ(CountNonZeroOutside(d, spans), 0);
  const auto e = SpanErrors(d, truth, spans);
  EXPECT_GT(e[0], 0.9) << "valid share";
  EXPECT_LT(e[1], 0.1);
  EXPECT_LT(e[2], 0.3);
}

// ---- The studio: the region's result against the full run -----------------

Rig SmallStereoRig() {
  auto rig = LoadRig(ShippedRigPath("studio-4"));
  HOLO_CHECK_MSG(rig.ok(), rig.status().ToString());
  return WithStereoPods(rig->Scaled(0.5), 0.15);  // 320x240
}

// The small rig's studio and its IR renderer (2 threads), and PatchMatch
// options for its pods (0.5-6 m, 2 threads).
struct StereoStudio {
  std::unique_ptr<SyntheticStudio> studio;
  std::unique_ptr<StereoStudioRenderer> renderer;
  const Rig& rig;
  explicit StereoStudio(const Rig& r) : rig(r) {
    StudioOptions so;
    so.threads = 2;
    auto s = SyntheticStudio::Create(rig, so);
    if (!s.ok()) return;
    studio = std::move(*s);
    auto rr = StereoStudioRenderer::Create(studio.get(), rig, StereoRenderOptions{});
    if (rr.ok()) renderer = std::move(*rr);
  }
  PatchMatchOptions Options() const {
    PatchMatchOptions o;
    StereoSearchRange(rig.pods[0], 0.5f, 6.0f, &o);
    o.threads = 2;
    return o;
  }
};

ImageRect MaskBox(const ImageGray8& mask) {
  ImageRect b{mask.width(), mask.height(), 0, 0};
  for (int y = 0; y < mask.height(); ++y)
    for (int x = 0; x < mask.width(); ++x)
      if (mask.at(x, y)) {
        b.x0 = std::min(b.x0, x);
        b.y0 = std::min(b.y0, y);
        b.x1 = std::max(b.x1, x + 1);
        b.y1 = std::max(b.y1, y + 1);
      }
  return b;
}

// The person's box widened by 16 px (the policy's margin at 30 fps is
// 4 + 8..12 px here): over the person's pixels (truth mask) the region's
// disparities agree with the full run's, also with the search range capped
// (measured on pods 0 and 2, frame 6: 0.08 and 0.45 % of the person's
// pixels more than 1 px apart or valid in one run only, capped 0.38 and
// 0.95 %; bad-2px against the truth: full 0.51 and 1.02 %, region 0.51 and
// 1.06 %, capped 0.45 and 0.95 %). Bounds: 2 % apart, bad-2px at most 1
// point worse.
TEST(PatchMatchRegionTest, StudioPersonRegionMatchesFullRun) {
  const Rig rig = SmallStereoRig();
  const StereoStudio st(rig);
  ASSERT_TRUE(st.renderer != nullptr);
  StereoStudioRenderer* const renderer = st.renderer.get();
  PatchMatchOptions o = st.Options();
  PatchMatchStereo pm(o);
  for (int pod : {0, 2}) {
    StereoPair pair;
    renderer->RenderPod(6, pod, &pair);
    const ImageRect box = MaskBox(pair.mask);
    ASSERT_FALSE(box.empty());
    const ImageRect region = ImageRect{box.x0 - 16, box.y0 - 16, box.x1 + 16, box.y1 + 16}.Clipped(320, 240);
    // The search range capped as the policy does: the person's largest
    // disparity + 3 px (10 cm nearer at 2 m is +1.1 px; margin 2 px).
    float d_person = 0;
    for (size_t i = 0; i < pair.mask.num_pixels(); ++i)
      if (pair.mask.data()[i]) d_person = std::max(d_person, pair.disparity.data()[i]);
    ImageFloat full, roi, capped;
    ASSERT_TRUE(pm.Compute(pair.left, pair.right, &full).ok());
    ASSERT_TRUE(pm.Compute(pair.left, pair.right, region, &roi).ok());
    ASSERT_TRUE(pm.Compute(pair.left, pair.right, region, d_person + 3.0f, &capped).ok());
    EXPECT_EQ(CountNonZeroOutside(roi, region), 0);
    EXPECT_EQ(CountNonZeroOutside(capped, region), 0);
    EXPECT_EQ(CountNonZeroOutside(pm.right_disparity(), pm.RightRegion(region, 320, 240, d_person + 3.0f)), 0);
    int person = 0, differ = 0, differ_c = 0, bad_full = 0, bad_roi = 0, bad_c = 0;
    for (int y = 0; y < 240; ++y)
      for (int x = 0; x < 320; ++x) {
        if (!pair.mask.at(x, y) || !(pair.disparity.at(x, y) > 0.0f)) continue;
        ++person;
        const float a = full.at(x, y), b = roi.at(x, y), c = capped.at(x, y), t = pair.disparity.at(x, y);
        differ += (a > 0.0f) != (b > 0.0f) || std::abs(a - b) > 1.0f;
        differ_c += (a > 0.0f) != (c > 0.0f) || std::abs(a - c) > 1.0f;
        bad_full += !(a > 0.0f) || std::abs(a - t) > 2.0f;
        bad_roi += !(b > 0.0f) || std::abs(b - t) > 2.0f;
        bad_c += !(c > 0.0f) || std::abs(c - t) > 2.0f;
      }
    ASSERT_GT(person, 1000);
    const double differ_pct = 100.0 * differ / person, differ_c_pct = 100.0 * differ_c / person;
    const double bad_full_pct = 100.0 * bad_full / person, bad_roi_pct = 100.0 * bad_roi / person;
    const double bad_c_pct = 100.0 * bad_c / person;
    std::printf("pod %d: region %dx%d, person %d px, differ %.2f %% (capped %.2f %%), bad2 full %.2f %% roi %.2f %% "
                "capped %.2f %%\n",
                pod, region.width(), region.height(), person, differ_pct, differ_c_pct, bad_full_pct, bad_roi_pct,
                bad_c_pct);
    EXPECT_LT(differ_pct, 2.0) << "pod " << pod;
    EXPECT_LT(differ_c_pct, 2.0) << "pod " << pod;
    EXPECT_LT(bad_roi_pct, bad_full_pct + 1.0) << "pod " << pod;
    EXPECT_LT(bad_c_pct, bad_full_pct + 1.0) << "pod " << pod;
  }
}

// A whole pair due (the first frame here) is searched with SGBM and matched
// with PatchMatch only around what SGBM found (StereoRoiOptions::
// search_with_sgbm): the region holds the person, nothing outside it gets
// depth, the person's depth is as good as a whole PatchMatch run's, and the
// next frame is a region frame again. With the search off the whole pair
// goes through PatchMatch as before.
TEST(StereoRoiPolicyTest, WholePairIsSearchedWithSgbmThenMatchedAroundThePerson) {
  const Rig rig = SmallStereoRig();
  const StereoStudio st(rig);
  ASSERT_TRUE(st.renderer != nullptr);
  StereoStudioRenderer* const renderer = st.renderer.get();
  PatchMatchOptions o = st.Options();
  o.temporal = true;
  for (int pod : {0, 2}) {
    StereoPair pair, next;
    renderer->RenderPod(6, pod, &pair);
    renderer->RenderPod(7, pod, &next);
    PatchMatchStereo pm(o), whole_pm(o);
    StereoRoiPolicy policy(rig.pods[static_cast<size_t>(pod)], StereoRoiOptions{});
    ASSERT_TRUE(policy.options().search_with_sgbm);
    ImageFloat d, whole;
    auto region = policy.Match(&pm, 6, pair.left, pair.right, &d);
    ASSERT_TRUE(region.ok()) << region.status().ToString();
    EXPECT_TRUE(policy.searched()) << "pod " << pod;
    EXPECT_FALSE(pm.last_was_temporal());
    EXPECT_GT(region->area(), 0);
    EXPECT_LT(region->area(), 320 * 240 * 6 / 10) << "pod " << pod;
    EXPECT_EQ(CountNonZeroOutside(d, *region), 0);
    ASSERT_TRUE(whole_pm.Compute(pair.left, pair.right, &whole).ok());
    int person = 0, inside = 0, bad = 0, bad_whole = 0;
    for (int y = 0; y < 240; ++y)
      for (int x = 0; x < 320; ++x) {
        const float t = pair.disparity.at(x, y);
        if (!pair.mask.at(x, y) || !(t > 0.0f)) continue;
        ++person;
        inside += region->Contains(x, y);
        bad += !(d.at(x, y) > 0.0f) || std::abs(d.at(x, y) - t) > 2.0f;
        bad_whole += !(whole.at(x, y) > 0.0f) || std::abs(whole.at(x, y) - t) > 2.0f;
      }
    ASSERT_GT(person, 1000);
    EXPECT_GT(inside, person * 995 / 1000) << "pod " << pod << ": the person inside the searched region";
    EXPECT_LT(100.0 * bad / person, 100.0 * bad_whole / person + 1.0) << "pod " << pod << ": bad-2px against a whole run";
    // The next frame: a region frame from the last planes.
    ASSERT_TRUE(policy.Match(&pm, 7, next.left, next.right, &d).ok());
    EXPECT_FALSE(policy.searched()) << "pod " << pod;
    EXPECT_TRUE(pm.last_was_temporal()) << "pod " << pod;
  }
  StereoRoiOptions off;
  off.search_with_sgbm = false;
  StereoRoiPolicy policy(rig.pods[0], off);
  PatchMatchStereo pm(o);
  StereoPair pair;
  renderer->RenderPod(6, 0, &pair);
  ImageFloat d;
  auto region = policy.Match(&pm, 6, pair.left, pair.right, &d);
  ASSERT_TRUE(region.ok());
  EXPECT_FALSE(policy.searched());
  EXPECT_TRUE(region->IsFull(320));
}

// Nothing in the capture volume (a textured wall 5 m away): the search finds
// no one, PatchMatch does not run, every disparity is 0, and the next frame
// is searched again.
TEST(StereoRoiPolicyTest, EmptyViewIsSearchedWithoutPatchMatch) {
  const Rig rig = SmallStereoRig();
  const PodCalibration& pod = rig.pods[0];
  const float d_wall = static_cast<float>(pod.stereo.ir.fx * pod.stereo.baseline_m / 5.0);
  ImageGray8 left, right;
  ImageFloat truth;
  SlantedPlane(pod.stereo.ir.width, pod.stereo.ir.height, 0.0f, 0.0f, d_wall, &left, &right, &truth);
  PatchMatchOptions o;
  StereoSearchRange(pod, 0.5f, 6.0f, &o);
  o.threads = 2;
  PatchMatchStereo pm(o);
  StereoRoiPolicy policy(pod, StereoRoiOptions{});
  for (int64_t f = 0; f < 3; ++f) {
    ImageFloat d(4, 4, 1.0f);  // stale contents and size: replaced
    auto region = policy.Match(&pm, f, left, right, &d);
    ASSERT_TRUE(region.ok());
    EXPECT_TRUE(policy.searched()) << "frame " << f;
    EXPECT_EQ(region->area(), 0) << "frame " << f;
    ASSERT_EQ(d.width(), pod.stereo.ir.width);
    ASSERT_EQ(d.height(), pod.stereo.ir.height);
    EXPECT_EQ(CountNonZeroOutside(d, RowSpans::FromRect(ImageRect{}, d.width(), d.height())), 0);
  }
  EXPECT_EQ(pm.right_disparity().width(), 0) << "PatchMatch ran";
}

// The site's stereo source with regions (the default): after a first frame
// matched whole, the next is matched around the person; the person's depth
// is as good as in StereoDepthTest.StudioSourceGivesDepthCloseToTruth, the
// walls get none.
TEST(StereoRoiSourceTest, StudioSourceMatchesAroundThePerson) {
  auto base = LoadRig(ShippedRigPath("studio-4"));
  ASSERT_TRUE(base.ok());
  StudioOptions so;
  so.threads = 2;
  auto studio = SyntheticStudio::Create(base->Scaled(0.5), so);
  ASSERT_TRUE(studio.ok());
  StereoDepthOptions o;
  o.patchmatch.threads = 2;
  ASSERT_TRUE(o.roi.enabled);
  auto src = StereoStudioSource::Create(studio->get(), o);
  ASSERT_TRUE(src.ok()) << src.status().ToString();
  RgbdFrameSet frames;
  std::vector<StereoPair> pairs;
  ASSERT_TRUE((*src)->RenderFrame(4, &frames, &pairs).ok());
  EXPECT_EQ((*src)->last_full_pods(), 4);
  ASSERT_TRUE((*src)->RenderFrame(5, &frames, &pairs).ok());
  EXPECT_EQ((*src)->last_full_pods(), 0);  // no pod's turn (phases 0, 3, 7, 11 of 15)
  EXPECT_LT((*src)->last_matched_fraction(), 0.6);
  for (size_t i = 0; i < frames.frames.size(); ++i) {
    const ImageDepth16& d = frames.frames[i].depth;
    const StereoPair& p = pairs[i];
    const double fb_mm = p.fx * p.baseline_m * 1000.0;
    std::vector<double> rel;
    int fg = 0, bg_with_depth = 0, bg = 0;
    for (int y = 0; y < d.height(); ++y)
      for (int x = 0; x < d.width(); ++x) {
        if (!(p.disparity.at(x, y) > 0)) continue;
        if (p.mask.at(x, y) == 0) {
          ++bg;
          bg_with_depth += d.at(x, y) != 0;
          continue;
        }
        ++fg;
        if (d.at(x, y) == 0) continue;
        const double z = fb_mm / p.disparity.at(x, y);
        rel.push_back(std::abs(d.at(x, y) - z) / z);
      }
    ASSERT_GT(fg, 0);
    EXPECT_GT(static_cast<double>(rel.size()) / fg, 0.8) << "pod " << i << ": foreground with stereo depth";
    std::sort(rel.begin(), rel.end());
    EXPECT_LT(rel[rel.size() / 2], 0.02) << "pod " << i << ": median relative depth error";
    EXPECT_LT(bg_with_depth, bg / 2) << "pod " << i << ": background outside the region has no depth";
  }
}

// ---- The region policy -----------------------------------------------------

// A synthetic pod view: disparity where "people" (pixel rectangles at a
// depth inside the capture volume) are, 0 elsewhere (an empty room, or
// walls beyond the volume: both count as background). The matcher is
// simulated: it gives the truth inside the region, 0 outside.
struct PolicyScene {
  PodCalibration pod;
  float person_disparity = 0;
  explicit PolicyScene(const Rig& rig) : pod(rig.pods[0]) {
    // The depth at which the optical axis passes the z axis: the rig's pods
    // look at the centre of the capture area.
    const Eigen::Vector3f c = pod.world_from_depth.translation();
    const float z = std::sqrt(c.x() * c.x() + c.y() * c.y());
    person_disparity = static_cast<float>(pod.stereo.ir.fx * pod.stereo.baseline_m / z);
  }
  ImageFloat Truth(const std::vector<ImageRect>& people) const {
    ImageFloat d(pod.stereo.ir.width, pod.stereo.ir.height, 0.0f);
    for (const ImageRect& p : people)
      for (int y = std::max(0, p.y0); y < std::min(d.height(), p.y1); ++y)
        for (int x = std::max(0, p.x0); x < std::min(d.width(), p.x1); ++x) d.at(x, y) = person_disparity;
    return d;
  }
  static ImageFloat Matched(const ImageFloat& truth, const ImageRect& region) {
    return Matched(truth, RowSpans::FromRect(region, truth.width(), truth.height()));
  }
  static ImageFloat Matched(const ImageFloat& truth, const RowSpans& region) {
    ImageFloat d(truth.width(), truth.height(), 0.0f);
    for (int y = 0; y < d.height(); ++y)
      for (int x = 0; x < d.width(); ++x)
        if (region.Contains(x, y)) d.at(x, y) = truth.at(x, y);
    return d;
  }
};

bool Covers(const ImageRect& outer, const ImageRect& inner) {
  return outer.x0 <= inner.x0 && outer.y0 <= inner.y0 && outer.x1 >= inner.x1 && outer.y1 >= inner.y1;
}
bool Covers(const RowSpans& outer, const ImageRect& inner) {
  for (int y = inner.y0; y < inner.y1; ++y)
    if (!outer.Contains(inner.x0, y) || !outer.Contains(inner.x1 - 1, y)) return false;
  return true;
}

TEST(StereoRoiPolicyTest, FollowsThePersonAndMatchesWholeWhenDue) {
  const Rig rig = SmallStereoRig();
  PolicyScene scene(rig);
  StereoRoiOptions o;  // 30 fps, full every 15 frames
  StereoRoiPolicy policy(scene.pod, o);
  const ImageRect full = ImageRect::Full(320, 240);
  // The pixels of the person's centre must lie in the capture volume.
  {
    const ImageFloat t = scene.Truth({ImageRect{150, 60, 170, 180}});
    policy.Update(0, full, t);
    ASSERT_FALSE(policy.foreground_box().empty()) << "the test's person is not in the capture volume";
    StereoRoiPolicy fresh(scene.pod, o);
    policy = fresh;
  }
  // A person walking right at 2 px per frame (~0.5 m/s at 2.5 m), 25 frames.
  int full_frames = 0;
  for (int f = 0; f < 25; ++f) {
    const ImageRect person{120 + 2 * f, 60, 160 + 2 * f, 180};
    const ImageRect region = policy.Next(f);
    if (region == full) ++full_frames;
    // The capped search range holds the person's disparity (nothing nearer moved in).
    if (region == full) {
      EXPECT_GT(policy.max_disparity(), 1e30f);
    } else {
      EXPECT_GT(policy.max_disparity(), scene.person_disparity + 1.0f) << "frame " << f;
      EXPECT_LT(policy.max_disparity(), scene.person_disparity + 6.0f) << "frame " << f;
    }
    EXPECT_TRUE(region == policy.spans().Bounds());
    EXPECT_TRUE(Covers(policy.spans(), person)) << "frame " << f;
    if (f > 0 && f % 15 != 0) {
      EXPECT_LT(region.area(), full.area() / 2) << "frame " << f;
    }
    policy.Update(f, policy.spans(), PolicyScene::Matched(scene.Truth({person}), policy.spans()));
  }
  EXPECT_EQ(full_frames, 2);  // frames 0 and 15
  // Off: always the whole image.
  StereoRoiOptions off = o;
  off.enabled = false;
  StereoRoiPolicy none(scene.pod, off);
  for (int f = 0; f < 3; ++f) {
    EXPECT_TRUE(none.Next(f) == full);
    none.Update(f, full, scene.Truth({ImageRect{120, 60, 160, 180}}));
  }
  // Nobody in view: every frame whole; a step back in time or a gap: whole.
  StereoRoiPolicy empty(scene.pod, o);
  for (int f = 0; f < 4; ++f) {
    const ImageRect region = empty.Next(f);
    EXPECT_TRUE(region == full) << "frame " << f;
    empty.Update(f, region, scene.Truth({}));
  }
  StereoRoiPolicy p2(scene.pod, o);
  p2.Update(10, full, scene.Truth({ImageRect{120, 60, 160, 180}}));
  EXPECT_FALSE(p2.Next(11) == full);
  EXPECT_TRUE(p2.Next(9) == full);
  EXPECT_TRUE(p2.Next(10 + 16) == full);  // 0.53 s later
}

TEST(StereoRoiPolicyTest, PersonAtTheImageBorderKeepsTheRegion) {
  const Rig rig = SmallStereoRig();
  PolicyScene scene(rig);
  StereoRoiOptions o;
  o.volume_radius_m = 2.0f;  // the image's edge at the centre's depth is 1.74 m from it
  StereoRoiPolicy policy(scene.pod, o);
  const ImageRect full = ImageRect::Full(320, 240);
  const ImageRect person{0, 50, 30, 180};  // cut by the left edge
  policy.Update(0, full, scene.Truth({person}));
  const ImageRect region = policy.Next(1);
  EXPECT_FALSE(region == full);
  EXPECT_TRUE(Covers(region, person));
  EXPECT_EQ(region.x0, 0);
  policy.Update(1, region, PolicyScene::Matched(scene.Truth({person}), region));
  EXPECT_FALSE(policy.full_due());  // the image's own edges do not count as touching
}

// Mismatches that land in the capture volume (thin streaks along rows, a
// small blob) do not stretch the person's box; a ball-sized blob does.
TEST(StereoRoiPolicyTest, MismatchStreaksDoNotStretchTheBox) {
  const Rig rig = SmallStereoRig();
  PolicyScene scene(rig);
  StereoRoiPolicy policy(scene.pod, StereoRoiOptions{});
  const ImageRect full = ImageRect::Full(320, 240);
  const ImageRect person{150, 60, 190, 180};
  std::vector<ImageRect> scene_parts = {person};
  for (int y = 160; y < 176; y += 5) scene_parts.push_back(ImageRect{40, y, 110, y + 2});  // streaks 2 px tall
  scene_parts.push_back(ImageRect{230, 100, 238, 108});                                    // an 8x8 px blob
  policy.Update(0, full, scene.Truth(scene_parts));
  const ImageRect box = policy.foreground_box();
  EXPECT_GE(box.x0, person.x0 - 2);
  EXPECT_LE(box.x1, person.x1 + 2);
  EXPECT_GE(box.y0, person.y0 - 2);
  EXPECT_LE(box.y1, person.y1 + 2);
  // A 20 px ball beside the person is kept.
  scene_parts.push_back(ImageRect{220, 150, 240, 170});
  policy.Update(1, full, scene.Truth(scene_parts));
  EXPECT_GE(policy.foreground_box().x1, 238);
}

// A person entering the view while another is matched: found on the next
// frame when they enter touching the region, and at the latest
// full_every − 1 frames after they appear anywhere else.
TEST(StereoRoiPolicyTest, PersonEnteringIsFoundWithinStatedFrames) {
  const Rig rig = SmallStereoRig();
  PolicyScene scene(rig);
  StereoRoiOptions o;
  const ImageRect first{60, 60, 100, 180};
  for (int appear = 1; appear < 20; ++appear) {
    StereoRoiPolicy policy(scene.pod, o);
    const ImageRect second{250, 70, 290, 190};  // far from the first
    int found = -1;
    for (int f = 0; f < appear + o.full_every + 1 && found < 0; ++f) {
      std::vector<ImageRect> people = {first};
      if (f >= appear) people.push_back(second);
      policy.Next(f);
      if (f >= appear && Covers(policy.spans(), second)) found = f;
      policy.Update(f, policy.spans(), PolicyScene::Matched(scene.Truth(people), policy.spans()));
    }
    ASSERT_GE(found, appear) << "appearing at frame " << appear;
    EXPECT_LE(found - appear, o.full_every - 1) << "appearing at frame " << appear;
  }
  // Entering next to the matched person (touching their region): the next frame.
  StereoRoiPolicy policy(scene.pod, o);
  policy.Update(0, ImageRect::Full(320, 240), scene.Truth({first}));
  const ImageRect region = policy.Next(1);
  const ImageRect beside{region.x1 - 3, 60, region.x1 + 40, 180};
  policy.Update(1, policy.spans(), PolicyScene::Matched(scene.Truth({first, beside}), policy.spans()));
  EXPECT_TRUE(policy.full_due());
  EXPECT_TRUE(policy.Next(2) == ImageRect::Full(320, 240));
}

// A person with arms out (a T: most of their box is empty): the spans
// follow them as they walk, covering every pixel of them, on under two
// thirds of the box (StereoRoiOptions::row_spans off: the box). A foot
// stepping out sideways past its rows' spans, still inside the box, asks
// for a full match on the next frame.
TEST(StereoRoiPolicyTest, RowSpansFollowThePersonOnLessThanTheBox) {
  const Rig rig = SmallStereoRig();
  PolicyScene scene(rig);
  StereoRoiOptions o;
  StereoRoiPolicy policy(scene.pod, o);
  StereoRoiOptions box_o = o;
  box_o.row_spans = false;
  StereoRoiPolicy box_policy(scene.pod, box_o);
  const ImageRect full = ImageRect::Full(320, 240);
  int full_frames = 0;
  for (int f = 0; f < 25; ++f) {
    const std::vector<ImageRect> person = {ImageRect{150 + 2 * f, 40, 170 + 2 * f, 200},   // body and legs
                                           ImageRect{100 + 2 * f, 80, 220 + 2 * f, 92}};   // arms
    const ImageRect region = policy.Next(f);
    const ImageRect box_region = box_policy.Next(f);
    if (region == full) {
      ++full_frames;
    } else {
      EXPECT_TRUE(box_policy.spans() == RowSpans::FromRect(box_region, 320, 240));
      EXPECT_TRUE(region == box_region) << "frame " << f;  // the spans' bounds are the box
      EXPECT_LT(policy.spans().area(), box_region.area() * 2 / 3) << "frame " << f;
    }
    for (const ImageRect& part : person) EXPECT_TRUE(Covers(policy.spans(), part)) << "frame " << f;
    policy.Update(f, policy.spans(), PolicyScene::Matched(scene.Truth(person), policy.spans()));
    box_policy.Update(f, box_policy.spans(), PolicyScene::Matched(scene.Truth(person), box_policy.spans()));
    EXPECT_FALSE(policy.full_due()) << "frame " << f;
  }
  EXPECT_EQ(full_frames, 2);  // frames 0 and 15
  // A foot out sideways at the bottom (rows 180-200) to where the arms' rows
  // reach, beyond the legs' spans.
  const ImageRect region = policy.Next(25);
  ASSERT_FALSE(region == full);
  const ImageRect foot{200 + 50, 182, 200 + 60, 200};
  ASSERT_FALSE(policy.spans().Contains(foot.x0, 190));
  ASSERT_TRUE(Covers(region, ImageRect{foot.x0 - 8, 182, foot.x0, 200}));  // inside the box
  const std::vector<ImageRect> person = {ImageRect{200, 40, 220, 200}, ImageRect{150, 80, 270, 92},
                                         ImageRect{220, 182, foot.x1, 200}};
  policy.Update(25, policy.spans(), PolicyScene::Matched(scene.Truth(person), policy.spans()));
  EXPECT_TRUE(policy.full_due());
  EXPECT_TRUE(policy.Next(26) == full);
}

TEST(StereoRoiPolicyTest, RefusesBadOptions) {
  StereoRoiOptions o;
  o.full_every = 0;
  EXPECT_NE(o.Check().message().find("full_every"), std::string::npos);
  o = StereoRoiOptions{};
  o.volume_max_z_m = 0.0f;
  EXPECT_NE(o.Check().message().find("volume_min_z_m"), std::string::npos);
  StereoDepthOptions sd;
  sd.roi.fps = 0;
  EXPECT_NE(sd.Check().message().find("fps"), std::string::npos);
}

}  // namespace
}  // namespace holo
