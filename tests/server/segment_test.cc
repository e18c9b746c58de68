#include "server/segment/segmenter.h"

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/image_io.h"
#include "common/metrics/image_metrics.h"
#include "common/visualize.h"
#include "server/segment/mog2_baseline.h"
#include "server/studio/studio.h"
#include "server/studio/workloads.h"

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
  EXPECT_GE(r.mean_iou, 0.90);
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

}  // namespace
}  // namespace holo
