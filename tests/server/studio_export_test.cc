// The studio → dataset path the demo uses: what is written reads back equal to
// what the studio renders, the contact sheet shows every pod, and the summary
// measures the noise model.
#include <gtest/gtest.h>

#include "common/image_io.h"
#include "common/visualize.h"
#include "server/capture/dataset.h"
#include "server/capture/studio_export.h"
#include "studio/studio.h"
#include "test_util.h"

namespace holo {
namespace {

Rig SmallRig() {
  auto rig = LoadRig(ShippedRigPath("studio-4"));
  HOLO_CHECK(rig.ok());
  return rig->Scaled(0.25);  // 160x120
}

TEST(StudioExportTest, WrittenDatasetReadsBackAsRendered) {
  StudioOptions options;
  options.seed = 11;
  SyntheticStudio studio(SmallRig(), options);
  const std::string dir = test::MakeTempDir("export") + "/ds";
  StudioExportOptions eo;
  eo.first_frame = 5;
  eo.num_frames = 3;
  eo.out_dir = dir;
  auto summary = ExportStudio(studio, eo);
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  EXPECT_EQ(summary->frames, 3);
  EXPECT_EQ(summary->pods, 4);

  auto reader = DatasetReader::Open(dir);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  ASSERT_EQ((*reader)->num_frames(), 3);
  ASSERT_TRUE((*reader)->has_ground_truth());
  RgbdFrameSet expected, got;
  StudioGroundTruth gt;
  for (int64_t i = 0; i < 3; ++i) {
    studio.RenderFrame(5 + i, &expected, &gt);
    ASSERT_TRUE((*reader)->Read(i, &got).ok());
    ASSERT_EQ(got.frames.size(), expected.frames.size());
    for (size_t p = 0; p < got.frames.size(); ++p) {
      EXPECT_TRUE(got.frames[p].color == expected.frames[p].color) << "frame " << i << " pod " << p;
      EXPECT_TRUE(got.frames[p].depth == expected.frames[p].depth) << "frame " << i << " pod " << p;
      EXPECT_EQ(got.frames[p].timestamp_us, expected.frames[p].timestamp_us);
    }
    auto mesh = (*reader)->ReadGroundTruthMesh(i);
    ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
    ASSERT_EQ(mesh->num_vertices(), gt.foreground_mesh.num_vertices());
    for (size_t v = 0; v < mesh->num_vertices(); v += 97)
      EXPECT_EQ(mesh->positions[v], gt.foreground_mesh.positions[v]);
  }
  // Writing into an existing dataset is refused, nothing is overwritten.
  auto again = ExportStudio(studio, eo);
  EXPECT_FALSE(again.ok());
}

TEST(StudioExportTest, SummaryMeasuresForegroundAndNoise) {
  StudioOptions options;
  SyntheticStudio studio(SmallRig(), options);
  StudioExportOptions eo;
  eo.num_frames = 2;
  auto noisy = ExportStudio(studio, eo);
  ASSERT_TRUE(noisy.ok());
  EXPECT_GT(noisy->foreground_fraction, 0.005);
  EXPECT_LT(noisy->foreground_fraction, 0.5);
  EXPECT_GT(noisy->fg_depth_median_abs_error_mm, 2.0) << "σ ≈ 3 mm · z², figure at ~2.5 m";
  EXPECT_LT(noisy->fg_depth_median_abs_error_mm, 40.0);
  EXPECT_GT(noisy->mesh_triangles, 1000u);

  options.depth_noise = false;
  SyntheticStudio clean(SmallRig(), options);
  auto exact = ExportStudio(clean, eo);
  ASSERT_TRUE(exact.ok());
  EXPECT_EQ(exact->depth_abs_error_mm, 0.0);
  EXPECT_EQ(exact->depth_valid_fraction, 1.0);
}

TEST(StudioExportTest, ContactSheetTilesColourDepthAndMaskOfEveryPod) {
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  StudioExportOptions eo;
  eo.num_frames = 1;
  auto summary = ExportStudio(studio, eo);
  ASSERT_TRUE(summary.ok());
  const ImageRgb8& sheet = summary->contact_sheet;
  // 4 pods in one group of 4 columns: rows colour, depth, mask; 4 px gaps.
  EXPECT_EQ(sheet.width(), 4 * 160 + 5 * 4);
  EXPECT_EQ(sheet.height(), 3 * 120 + 4 * 4);
  const std::string path = test::MakeTempDir("sheet") + "/sheet.png";
  ASSERT_TRUE(WriteImageRgb8(path, sheet).ok());
  auto back = ReadImageRgb8(path);
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(*back == sheet);
}

TEST(StudioExportTest, RejectsBadSpans) {
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  StudioExportOptions eo;
  eo.num_frames = 0;
  EXPECT_EQ(ExportStudio(studio, eo).status().code(), StatusCode::kInvalidArgument);
  eo.num_frames = 1;
  eo.first_frame = -3;
  EXPECT_EQ(ExportStudio(studio, eo).status().code(), StatusCode::kInvalidArgument);
}

TEST(VisualizeTest, DepthColourMapMarksInvalidBlackAndOrdersNearFar) {
  ImageDepth16 d(3, 1);
  d.at(0, 0) = 0;
  d.at(1, 0) = 1000;
  d.at(2, 0) = 5000;
  const ImageRgb8 c = ColorizeDepth(d, 1000, 5000);
  EXPECT_EQ(c.at(0, 0, 0) + c.at(0, 0, 1) + c.at(0, 0, 2), 0);
  EXPECT_GT(c.at(1, 0, 0), c.at(2, 0, 0)) << "near is warm (more red)";
  EXPECT_LT(c.at(1, 0, 2), c.at(2, 0, 2) + 1) << "far is cool";
}

}  // namespace
}  // namespace holo
