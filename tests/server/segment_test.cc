#include "server/segment/segmenter.h"

#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "common/metrics/image_metrics.h"
#include "common/visualize.h"
#include "server/segment/mog2_baseline.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

// HOLO_SEGMENT_DUMP=/some/dir writes masks for inspection.
const char* DumpDir() { return std::getenv("HOLO_SEGMENT_DUMP"); }

Rig QvgaRig() {
  auto w = GetWorkload("S8-QVGA");
  HOLO_CHECK_MSG(w.ok(), w.status().ToString());
  return w->rig;
}

StudioOptions QvgaStudio(bool empty) {
  auto w = GetWorkload("S8-QVGA");
  HOLO_CHECK_MSG(w.ok(), w.status().ToString());
  StudioOptions o = w->studio;
  o.empty_room = empty;
  o.threads = 2;
  return o;
}

// Background from `n` empty-room frames of the S8-QVGA studio.
void LearnBackground(const Rig& rig, Segmenter* seg, int n, Mog2Segmenter* mog2 = nullptr) {
  SyntheticStudio empty(rig, QvgaStudio(true));
  RgbdFrameSet fs;
  for (int k = 0; k < n; ++k) {
    empty.RenderFrame(k, &fs, nullptr);
    ASSERT_TRUE(seg->AddBackgroundFrame(fs).ok());
    if (mog2) {
      ASSERT_TRUE(mog2->AddBackgroundFrame(fs).ok());
    }
  }
  ASSERT_TRUE(seg->FinishBackground().ok());
}

struct IouResult {
  double mean_iou = 0, min_iou = 1;
  double unary_iou = 0;
};

IouResult MeasureIou(const Rig& rig, Segmenter* seg, const std::vector<int>& frame_ids, const std::string& tag) {
  SyntheticStudio studio(rig, QvgaStudio(false));
  RgbdFrameSet fs;
  StudioGroundTruth gt;
  std::vector<SegmentDebug> dbg;
  IouResult r;
  int count = 0;
  for (int id : frame_ids) {
    studio.RenderFrame(id, &fs, &gt);
    EXPECT_TRUE(seg->Segment(&fs, &dbg).ok());
    for (size_t p = 0; p < fs.frames.size(); ++p) {
      auto o = metrics::CompareMasks(fs.frames[p].mask, gt.mask[p]);
      auto u = metrics::CompareMasks(dbg[p].unary_mask, gt.mask[p]);
      EXPECT_TRUE(o.ok() && u.ok());
      r.mean_iou += o->iou;
      r.unary_iou += u->iou;
      r.min_iou = std::min(r.min_iou, o->iou);
      ++count;
    }
    if (const char* dir = DumpDir()) {
      // Per frame: comparison (green: both, red: false positive, blue:
      // missed) and unary-only comparison, all pods tiled.
      std::vector<ImageRgb8> cmp(2 * fs.frames.size());
      for (size_t p = 0; p < fs.frames.size(); ++p) {
        for (int k = 0; k < 2; ++k) {
          const ImageGray8& mask = k == 0 ? fs.frames[p].mask : dbg[p].unary_mask;
          ImageRgb8& out = cmp[k * fs.frames.size() + p];
          out.Resize(mask.width(), mask.height());
          for (int y = 0; y < out.height(); ++y)
            for (int x = 0; x < out.width(); ++x) {
              const bool m = mask.at(x, y) != 0, t = gt.mask[p].at(x, y) != 0;
              const uint8_t* c = &fs.frames[p].color.at(x, y, 0);
              uint8_t* o = &out.at(x, y, 0);
              const uint8_t g = static_cast<uint8_t>((c[0] + c[1] + c[2]) / 6);
              o[0] = o[1] = o[2] = g;
              if (m && t) o[1] = 200;
              if (m && !t) o[0] = 255;
              if (!m && t) o[2] = 255;
            }
        }
      }
      std::vector<const ImageRgb8*> tiles;
      for (const auto& c : cmp) tiles.push_back(&c);
      (void)WriteImageRgb8(std::string(dir) + "/" + tag + "_f" + std::to_string(id) + ".png", TileImages(tiles, 4));
    }
  }
  r.mean_iou /= count;
  r.unary_iou /= count;
  return r;
}

TEST(SegmenterTest, MaskIouOnQvgaStudio) {
  const Rig rig = QvgaRig();
  Segmenter seg(rig, SegmenterOptions{});
  LearnBackground(rig, &seg, 20);
  const IouResult r = MeasureIou(rig, &seg, {5, 45, 95, 150}, "crf");
  std::printf("mask IoU: mean %.4f, min %.4f, unary only %.4f\n", r.mean_iou, r.min_iou, r.unary_iou);
  // Measured (20 background frames, frames 5/45/95/150, 8 pods): mean
  // 0.969, min 0.938, unary only 0.965.
  EXPECT_GE(r.mean_iou, 0.962);
  EXPECT_GE(r.min_iou, 0.925);
  EXPECT_GE(r.mean_iou, r.unary_iou) << "the CRF must not be worse than the unary term";
}

TEST(SegmenterTest, Mog2Baseline) {
  const Rig rig = QvgaRig();
  Segmenter seg(rig, SegmenterOptions{});
  Mog2Segmenter mog2(static_cast<int>(rig.pods.size()), Mog2Options{});
  LearnBackground(rig, &seg, 20, &mog2);
  SyntheticStudio studio(rig, QvgaStudio(false));
  RgbdFrameSet fs;
  StudioGroundTruth gt;
  double sum = 0;
  int n = 0;
  for (int id : {5, 95}) {
    studio.RenderFrame(id, &fs, &gt);
    ASSERT_TRUE(mog2.Segment(&fs).ok());
    for (size_t p = 0; p < fs.frames.size(); ++p) {
      auto o = metrics::CompareMasks(fs.frames[p].mask, gt.mask[p]);
      ASSERT_TRUE(o.ok());
      sum += o->iou;
      ++n;
    }
  }
  std::printf("MOG2 mask IoU: %.4f\n", sum / n);
}

// Pixels of the figure's (and ball's) floor shadow: background in the truth,
// clearly darker than the empty room at the same pixel, and not next to
// the foreground (mask edges are judged by the IoU test).
TEST(SegmenterTest, FloorShadowStaysBackground) {
  const Rig rig = QvgaRig();
  Segmenter seg(rig, SegmenterOptions{});
  LearnBackground(rig, &seg, 20);
  SyntheticStudio empty(rig, QvgaStudio(true)), studio(rig, QvgaStudio(false));
  RgbdFrameSet room, fs;
  StudioGroundTruth gt;
  size_t shadow = 0, kept = 0;
  for (int id : {10, 60, 120}) {
    empty.RenderFrame(id, &room, nullptr);
    studio.RenderFrame(id, &fs, &gt);
    ASSERT_TRUE(seg.Segment(&fs).ok());
    for (size_t p = 0; p < fs.frames.size(); ++p) {
      const ImageGray8& truth = gt.mask[p];
      for (int y = 3; y + 3 < truth.height(); ++y)
        for (int x = 3; x + 3 < truth.width(); ++x) {
          bool near_fg = false;
          for (int dy = -3; dy <= 3 && !near_fg; ++dy)
            for (int dx = -3; dx <= 3; ++dx) near_fg |= truth.at(x + dx, y + dy) != 0;
          if (near_fg) continue;
          const uint8_t* c = &fs.frames[p].color.at(x, y, 0);
          const uint8_t* e = &room.frames[p].color.at(x, y, 0);
          const int now = c[0] + c[1] + c[2], before = e[0] + e[1] + e[2];
          if (before < 30 || now > 0.85 * before) continue;
          ++shadow;
          if (fs.frames[p].mask.at(x, y) == 0) ++kept;
        }
    }
  }
  const double fraction = static_cast<double>(kept) / static_cast<double>(shadow);
  std::printf("shadow pixels: %zu, kept background: %.4f\n", shadow, fraction);
  ASSERT_GT(shadow, 1000u) << "the test frames should contain floor shadows";
  EXPECT_GE(fraction, 0.98);
}

// One pod facing a flat grey wall 3 m away; a grey board (same colour)
// 30 cm in front of it must be found by the depth term alone.
Rig GreyWallRig() {
  Rig rig;
  rig.name = "grey";
  PodCalibration pod;
  pod.name = "pod0";
  pod.depth = pod.color = Intrinsics::FromFov(160, 120, 60.0);
  rig.pods.push_back(pod);
  return rig;
}

RgbdFrameSet GreyWallFrame(uint16_t wall_mm, int seed) {
  RgbdFrameSet fs;
  fs.frames.resize(1);
  RgbdFrame& f = fs.frames[0];
  f.color.Resize(160, 120, 128);
  f.depth.Resize(160, 120);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x)  // ±20 mm deterministic "noise"
      f.depth.at(x, y) = static_cast<uint16_t>(wall_mm + ((x * 7 + y * 13 + seed * 29) % 41) - 20);
  return fs;
}

TEST(SegmenterTest, GreyBoardOnGreyWallFoundByDepth) {
  const Rig rig = GreyWallRig();
  Segmenter seg(rig, SegmenterOptions{});
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(seg.AddBackgroundFrame(GreyWallFrame(3000, k)).ok());
  ASSERT_TRUE(seg.FinishBackground().ok());
  RgbdFrameSet fs = GreyWallFrame(3000, 99);
  ImageGray8 truth(160, 120);
  for (int y = 30; y < 90; ++y)
    for (int x = 50; x < 110; ++x) {
      fs.frames[0].depth.at(x, y) = static_cast<uint16_t>(fs.frames[0].depth.at(x, y) - 300);
      truth.at(x, y) = 255;
    }
  ASSERT_TRUE(seg.Segment(&fs).ok());
  auto o = metrics::CompareMasks(fs.frames[0].mask, truth);
  ASSERT_TRUE(o.ok());
  std::printf("grey board IoU %.4f\n", o->iou);
  // Measured 0.962: the board's 1-pixel rim is a depth edge, where depth
  // evidence is capped and the colour (same grey) cannot help.
  EXPECT_GE(o->iou, 0.95);
  // The empty wall alone stays background.
  RgbdFrameSet wall = GreyWallFrame(3000, 5);
  ASSERT_TRUE(seg.Segment(&wall).ok());
  size_t fg = 0;
  for (uint8_t v : wall.frames[0].mask.storage()) fg += v != 0;
  EXPECT_EQ(fg, 0u);
}

// Stereo depth at a person's edge (docs/stereo.md, "Stereo depth at the
// site"): left of a red board 2.5 m away, an empty strip (the wall the other
// camera cannot see) and then 3 pixels of wall carrying the board's depth
// (the matcher spread it past the edge). The wall's colour says background
// there; only with depth_edge_band_px does colour get to decide.
TEST(SegmenterTest, EdgeBandLetsColourDecideBesideStereoEdges) {
  const Rig rig = GreyWallRig();
  auto run = [&](int band_px, double* spread_fg, double* board_iou) {
    SegmenterOptions o;
    o.depth_edge_band_px = band_px;
    Segmenter seg(rig, o);
    for (int k = 0; k < 10; ++k) ASSERT_TRUE(seg.AddBackgroundFrame(GreyWallFrame(3000, k)).ok());
    ASSERT_TRUE(seg.FinishBackground().ok());
    RgbdFrameSet fs = GreyWallFrame(3000, 99);
    RgbdFrame& f = fs.frames[0];
    ImageGray8 truth(160, 120);
    size_t spread = 0, spread_on = 0;
    for (int y = 30; y < 90; ++y) {
      for (int x = 36; x < 44; ++x) f.depth.at(x, y) = 0;  // occluded: no depth
      for (int x = 44; x < 110; ++x) {
        f.depth.at(x, y) = static_cast<uint16_t>(2500 + (x + y) % 7);
        if (x < 47) continue;  // the spread band keeps the wall's grey
        truth.at(x, y) = 255;
        f.color.at(x, y, 0) = 200;
        f.color.at(x, y, 1) = 40;
        f.color.at(x, y, 2) = 40;
      }
    }
    ASSERT_TRUE(seg.Segment(&fs).ok());
    for (int y = 30; y < 90; ++y)
      for (int x = 44; x < 47; ++x) {
        ++spread;
        spread_on += f.mask.at(x, y) != 0;
      }
    *spread_fg = static_cast<double>(spread_on) / static_cast<double>(spread);
    auto iou = metrics::CompareMasks(f.mask, truth);
    ASSERT_TRUE(iou.ok());
    *board_iou = iou->iou;
  };
  double spread0 = 0, iou0 = 0, spread3 = 0, iou3 = 0;
  run(0, &spread0, &iou0);
  run(3, &spread3, &iou3);
  std::printf("spread band foreground: %.3f without the edge band, %.3f with 3 px; board IoU %.4f / %.4f\n", spread0,
              spread3, iou0, iou3);
  EXPECT_GE(spread0, 0.8) << "without the band the spread depth makes the wall foreground";
  EXPECT_LE(spread3, 0.1);
  EXPECT_GE(iou3, 0.95);
}

// Both segmenters learn the same `frames` empty-room frame sets.
void LearnBackground(SyntheticStudio& empty, int frames, std::initializer_list<Segmenter*> segs) {
  RgbdFrameSet fs;
  for (int k = 0; k < frames; ++k) {
    empty.RenderFrame(k, &fs, nullptr);
    for (Segmenter* s : segs) ASSERT_TRUE(s->AddBackgroundFrame(fs).ok());
  }
  for (Segmenter* s : segs) ASSERT_TRUE(s->FinishBackground().ok());
}

// The vectorised unary term (AVX2, where the CPU has it) gives the portable
// path's log-odds bit for bit, depth edges included, and so the same masks.
TEST(SegmenterTest, VectorisedUnaryMatchesThePortablePath) {
  const Rig rig = QvgaRig();
  SegmenterOptions scalar;
  scalar.simd = false;
  Segmenter a(rig, SegmenterOptions{}), b(rig, scalar);
  SyntheticStudio empty(rig, QvgaStudio(true)), studio(rig, QvgaStudio(false));
  RgbdFrameSet fs;
  ASSERT_NO_FATAL_FAILURE(LearnBackground(empty, 5, {&a, &b}));
  for (int k : {12, 40}) {
    studio.RenderFrame(k, &fs, nullptr);
    RgbdFrameSet fa = fs, fb = fs;
    std::vector<SegmentDebug> da, db;
    ASSERT_TRUE(a.Segment(&fa, &da).ok());
    ASSERT_TRUE(b.Segment(&fb, &db).ok());
    size_t fg = 0;
    for (size_t p = 0; p < fs.frames.size(); ++p) {
      const ImageFloat& ua = da[p].unary_logodds;
      const ImageFloat& ub = db[p].unary_logodds;
      ASSERT_EQ(ua.width(), ub.width());
      ASSERT_EQ(ua.height(), ub.height());
      const size_t n = static_cast<size_t>(ua.width()) * ua.height();
      for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(ua.data()[i], ub.data()[i]) << "pod " << p << " pixel " << i;
        fg += ua.data()[i] > 0;
      }
      EXPECT_TRUE(fa.frames[p].mask == fb.frames[p].mask) << p;
    }
    EXPECT_GT(fg, 5000u) << "the person is in view";
  }
}

TEST(SegmenterTest, SameMasksForAnyThreadCountAndRepeatedCalls) {
  const Rig rig = QvgaRig().Scaled(0.5);  // 160x120
  SegmenterOptions o1;
  o1.threads = 1;
  SegmenterOptions o2 = o1;
  o2.threads = 2;
  Segmenter a(rig, o1), b(rig, o2);
  SyntheticStudio empty(rig, QvgaStudio(true)), studio(rig, QvgaStudio(false));
  RgbdFrameSet fs;
  ASSERT_NO_FATAL_FAILURE(LearnBackground(empty, 5, {&a, &b}));
  studio.RenderFrame(30, &fs, nullptr);
  RgbdFrameSet fa = fs, fb = fs;
  ASSERT_TRUE(a.Segment(&fa).ok());
  ASSERT_TRUE(b.Segment(&fb).ok());
  RgbdFrameSet again = fs;
  ASSERT_TRUE(b.Segment(&again).ok());
  for (size_t p = 0; p < fs.frames.size(); ++p) {
    EXPECT_TRUE(fa.frames[p].mask == fb.frames[p].mask) << p;
    EXPECT_TRUE(again.frames[p].mask == fb.frames[p].mask) << p;
  }
}

// Pods whose colour camera is offset from the depth camera (a real
// Kinect-like pod): colour is sampled into the depth camera through depth.
double SmallRigIou(const Rig& rig) {
  Segmenter seg(rig, SegmenterOptions{});
  SyntheticStudio empty(rig, QvgaStudio(true)), studio(rig, QvgaStudio(false));
  RgbdFrameSet fs;
  StudioGroundTruth gt;
  for (int k = 0; k < 8; ++k) {
    empty.RenderFrame(k, &fs, nullptr);
    HOLO_CHECK(seg.AddBackgroundFrame(fs).ok());
  }
  HOLO_CHECK(seg.FinishBackground().ok());
  double iou = 0;
  int n = 0;
  for (int id : {50, 120}) {
    studio.RenderFrame(id, &fs, &gt);
    HOLO_CHECK(seg.Segment(&fs).ok());
    for (size_t p = 0; p < fs.frames.size(); ++p) {
      HOLO_CHECK(fs.frames[p].mask.width() == rig.pods[p].depth.width);
      auto o = metrics::CompareMasks(fs.frames[p].mask, gt.mask[p]);
      HOLO_CHECK(o.ok());
      iou += o->iou;
      ++n;
    }
    if (const char* dir = DumpDir()) {
      std::vector<ImageRgb8> tiles;
      for (size_t p = 0; p < fs.frames.size(); ++p) {
        ImageRgb8 t(gt.mask[p].width(), gt.mask[p].height());
        for (int y = 0; y < t.height(); ++y)
          for (int x = 0; x < t.width(); ++x) {
            const bool m = fs.frames[p].mask.at(x, y) != 0, g = gt.mask[p].at(x, y) != 0;
            t.at(x, y, 0) = m && !g ? 255 : 0;
            t.at(x, y, 1) = m && g ? 200 : 0;
            t.at(x, y, 2) = !m && g ? 255 : 0;
          }
        tiles.push_back(std::move(t));
      }
      std::vector<const ImageRgb8*> ptrs;
      for (const auto& t : tiles) ptrs.push_back(&t);
      (void)WriteImageRgb8(std::string(dir) + "/small_" + rig.name + std::to_string(rig.pods[0].IsRegistered()) +
                               "_f" + std::to_string(id) + ".png",
                           TileImages(ptrs, 4));
    }
  }
  return iou / n;
}

TEST(SegmenterTest, NonRegisteredPods) {
  const Rig registered = QvgaRig().Scaled(0.5);  // 160x120
  Rig rig = registered;
  for (auto& pod : rig.pods) {
    pod.color_from_depth = Pose::Identity();
    pod.color_from_depth.translation() = Eigen::Vector3f(-0.025f, 0.0f, 0.0f);
    pod.color = pod.color.Scaled(2.0);  // colour at 320x240, depth at 160x120
  }
  ASSERT_TRUE(rig.Check().ok());
  ASSERT_FALSE(rig.pods[0].IsRegistered());
  const double iou_registered = SmallRigIou(registered), iou = SmallRigIou(rig);
  std::printf("160x120 depth: IoU registered %.4f, non-registered (320x240 colour, 2.5 cm baseline) %.4f\n",
              iou_registered, iou);
  // Measured: registered 0.932, non-registered 0.881 (0.900 with the same
  // 2× colour but no baseline). The gap is a known limitation
  // (docs/segmentation.md); this bound catches a broken registration.
  EXPECT_GE(iou, iou_registered - 0.07);
  EXPECT_GE(iou, 0.86);
}

TEST(SegmenterTest, BadInputsGiveClearErrors) {
  const Rig rig = QvgaRig().Scaled(0.5);
  Segmenter seg(rig, SegmenterOptions{});
  SyntheticStudio empty(rig, QvgaStudio(true));
  RgbdFrameSet fs;
  empty.RenderFrame(0, &fs, nullptr);

  Status st = seg.Segment(&fs);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("no background model"), std::string::npos) << st.message();
  st = seg.FinishBackground();
  EXPECT_NE(st.message().find("no background frame"), std::string::npos) << st.message();

  RgbdFrameSet missing = fs;
  missing.frames.pop_back();
  st = seg.AddBackgroundFrame(missing);
  EXPECT_NE(st.message().find("7 pods, the rig has 8"), std::string::npos) << st.message();

  RgbdFrameSet wrong = fs;
  wrong.frames[2].depth.Resize(10, 10);
  st = seg.AddBackgroundFrame(wrong);
  EXPECT_NE(st.message().find("pod 2 depth is 10x10, the rig says 160x120"), std::string::npos) << st.message();
  wrong = fs;
  wrong.frames[5].color = ImageRgb8();
  st = seg.AddBackgroundFrame(wrong);
  EXPECT_NE(st.message().find("pod 5 colour is 0x0"), std::string::npos) << st.message();

  ASSERT_TRUE(seg.AddBackgroundFrame(fs).ok());
  ASSERT_TRUE(seg.FinishBackground().ok());
  EXPECT_TRUE(seg.has_background());
  st = seg.Segment(&missing);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("7 pods"), std::string::npos) << st.message();
  EXPECT_FALSE(seg.Segment(nullptr).ok());
  EXPECT_TRUE(seg.Segment(&fs).ok());

  SegmenterOptions bad;
  bad.depth_sigma_m = -1;
  EXPECT_NE(bad.Check().message().find("depth_sigma_m must be > 0"), std::string::npos);
  bad = SegmenterOptions{};
  bad.downsample = 3;
  EXPECT_NE(bad.Check().message().find("downsample must be 1, 2 or 4, got 3"), std::string::npos);
  EXPECT_TRUE(SegmenterOptions{}.Check().ok());
}

}  // namespace
}  // namespace holo
