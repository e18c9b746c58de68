// The capture site on the pipeline with the real stages: nothing lost, order
// kept, concurrent = serial, and clear errors for broken inputs.
#include <filesystem>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "server/capture/dataset.h"
#include "server/capture/studio_export.h"
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "test_util.h"

namespace holo {
namespace {

Rig SmallRig() {
  auto rig = LoadRig(ShippedRigPath("studio-4"));
  HOLO_CHECK(rig.ok());
  return rig->Scaled(0.25);  // 160x120
}

struct Result {
  std::vector<int64_t> frames;
  std::vector<Mesh> meshes;
};

Result RunSite(bool serial, int frames, MaskSource masks = MaskSource::kSegment, bool temporal = false,
               bool hull = false) {
  StudioOptions so;
  so.seed = 5;
  SyntheticStudio studio(SmallRig(), so);
  so.empty_room = true;
  SyntheticStudio empty(SmallRig(), so);
  CaptureSiteOptions o;
  o.masks = masks;
  o.background_frames = 5;
  // 4 pods at 160x120 share too little of the room for colour calibration.
  o.color_calibration = false;
  o.tsdf.voxel_size = 0.016f;
  o.pipeline.serial = serial;
  o.pipeline.max_frames = frames;
  o.temporal = temporal;
  o.temporal_options.track_points = 1000;
  o.hull = hull;
  auto site = CaptureSite::Create(&studio, &empty, &studio, o);
  EXPECT_TRUE(site.ok()) << site.status().ToString();
  Result r;
  if (!site.ok()) return r;
  auto stats = (*site)->Run([&](const FrameWork& w) {
    r.frames.push_back(w.frames.frame_index);
    r.meshes.push_back(w.mesh);
    return OkStatus();
  });
  EXPECT_TRUE(stats.ok()) << stats.status().ToString();
  return r;
}

TEST(CaptureSiteTest, ConcurrentPipelineEqualsSerialAndKeepsEveryFrameInOrder) {
  const Result serial = RunSite(true, 12);
  const Result concurrent = RunSite(false, 12);
  ASSERT_EQ(serial.frames.size(), 12u);
  ASSERT_EQ(concurrent.frames.size(), 12u);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(concurrent.frames[static_cast<size_t>(i)], i);
  for (size_t i = 0; i < 12; ++i) {
    const Mesh& a = serial.meshes[i];
    const Mesh& b = concurrent.meshes[i];
    ASSERT_GT(a.num_triangles(), 100u) << "frame " << i << ": a person was reconstructed";
    ASSERT_EQ(a.num_vertices(), b.num_vertices()) << "frame " << i;
    ASSERT_EQ(a.triangles, b.triangles) << "frame " << i;
    EXPECT_EQ(a.positions, b.positions) << "frame " << i;
    EXPECT_EQ(a.colors, b.colors) << "frame " << i;
  }
}

TEST(CaptureSiteTest, TemporalFusionStageRunsAndConcurrentEqualsSerial) {
  const Result serial = RunSite(true, 8, MaskSource::kTruth, true);
  const Result concurrent = RunSite(false, 8, MaskSource::kTruth, true);
  ASSERT_EQ(serial.frames.size(), 8u);
  ASSERT_EQ(concurrent.frames.size(), 8u);
  const Result per_frame = RunSite(true, 8, MaskSource::kTruth, false);
  ASSERT_EQ(per_frame.frames.size(), 8u);
  bool differs = false;
  for (size_t i = 0; i < 8; ++i) {
    EXPECT_EQ(concurrent.frames[i], static_cast<int64_t>(i));
    EXPECT_GT(serial.meshes[i].triangles.size(), 100u) << "frame " << i;
    EXPECT_EQ(serial.meshes[i].positions, concurrent.meshes[i].positions) << "frame " << i;
    EXPECT_EQ(serial.meshes[i].triangles, concurrent.meshes[i].triangles) << "frame " << i;
    // Frame 0 is per-frame fusion in both modes; later frames carry the past.
    if (i > 0) differs = differs || serial.meshes[i].positions != per_frame.meshes[i].positions;
  }
  EXPECT_TRUE(differs) << "temporal option had no effect";
}

TEST(CaptureSiteTest, VisualHullStageRunsFromMasksAndConcurrentEqualsSerial) {
  const Result serial = RunSite(true, 4, MaskSource::kTruth, false, true);
  const Result concurrent = RunSite(false, 4, MaskSource::kTruth, false, true);
  const Result fused = RunSite(true, 4, MaskSource::kTruth, false, false);
  ASSERT_EQ(serial.frames.size(), 4u);
  ASSERT_EQ(concurrent.frames.size(), 4u);
  ASSERT_EQ(fused.frames.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_GT(serial.meshes[i].num_triangles(), 100u) << "frame " << i << ": a hull was carved";
    EXPECT_EQ(serial.meshes[i].positions, concurrent.meshes[i].positions) << "frame " << i;
    EXPECT_NE(serial.meshes[i].positions, fused.meshes[i].positions) << "frame " << i << ": the hull, not the fusion";
  }
}

TEST(CaptureSiteTest, VisualHullOptionsAreChecked) {
  StudioOptions so;
  SyntheticStudio studio(SmallRig(), so);
  CaptureSiteOptions o;
  o.masks = MaskSource::kTruth;
  o.color_calibration = false;
  o.hull = true;
  o.temporal = true;
  auto site = CaptureSite::Create(&studio, nullptr, &studio, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().ToString().find("temporal"), std::string::npos) << site.status().ToString();
  o.temporal = false;
  o.masks = MaskSource::kNone;
  site = CaptureSite::Create(&studio, nullptr, &studio, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().ToString().find("needs masks"), std::string::npos) << site.status().ToString();
  o.masks = MaskSource::kTruth;
  o.hull_options.min_views = 0;
  site = CaptureSite::Create(&studio, nullptr, &studio, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().ToString().find("min_views"), std::string::npos) << site.status().ToString();
}

TEST(CaptureSiteTest, TemporalOptionsAreChecked) {
  StudioOptions so;
  SyntheticStudio studio(SmallRig(), so);
  CaptureSiteOptions o;
  o.masks = MaskSource::kTruth;
  o.color_calibration = false;
  o.temporal = true;
  o.temporal_options.max_weight = -1;
  auto site = CaptureSite::Create(&studio, nullptr, &studio, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().ToString().find("temporal"), std::string::npos) << site.status().ToString();
}

TEST(CaptureSiteTest, TruthMasksNeedTheStudio) {
  CaptureSiteOptions o;
  o.masks = MaskSource::kTruth;
  o.color_calibration = false;
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  auto site = CaptureSite::Create(&studio, nullptr, nullptr, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().message().find("truth"), std::string::npos);
}

TEST(CaptureSiteTest, SegmentationWithoutBackgroundIsRefused) {
  CaptureSiteOptions o;
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  auto site = CaptureSite::Create(&studio, nullptr, nullptr, o);
  ASSERT_FALSE(site.ok());
  EXPECT_NE(site.status().message().find("empty-room"), std::string::npos) << site.status().message();
}

TEST(CaptureSiteTest, DatasetWithAMissingPodImageFailsNamingTheFile) {
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  const std::string dir = test::MakeTempDir("site") + "/ds";
  StudioExportOptions eo;
  eo.num_frames = 3;
  eo.out_dir = dir;
  eo.ground_truth = false;
  ASSERT_TRUE(ExportStudio(studio, eo).ok());
  const std::string missing = dir + "/pod2/depth/000001.png";
  ASSERT_TRUE(std::filesystem::remove(missing));
  auto reader = DatasetReader::Open(dir);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  CaptureSiteOptions o;
  o.masks = MaskSource::kNone;
  o.color_calibration = false;
  o.tsdf.voxel_size = 0.02f;
  auto site = CaptureSite::Create(reader->get(), nullptr, nullptr, o);
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  int delivered = 0;
  auto stats = (*site)->Run([&](const FrameWork&) {
    ++delivered;
    return OkStatus();
  });
  ASSERT_FALSE(stats.ok());
  EXPECT_NE(stats.status().message().find("pod2/depth/000001.png"), std::string::npos) << stats.status().message();
  EXPECT_EQ(delivered, 1) << "frame 0 was complete and delivered; nothing after the bad one";
}

TEST(CaptureSiteTest, DatasetWithBadCalibrationIsRefusedAtOpen) {
  SyntheticStudio studio(SmallRig(), StudioOptions{});
  const std::string dir = test::MakeTempDir("site") + "/ds";
  StudioExportOptions eo;
  eo.num_frames = 1;
  eo.out_dir = dir;
  ASSERT_TRUE(ExportStudio(studio, eo).ok());
  auto text = ReadFileToString(dir + "/rig.yaml");
  ASSERT_TRUE(text.ok());
  std::string broken = *text;
  const size_t at = broken.find("fx: ");
  ASSERT_NE(at, std::string::npos);
  broken.replace(at, 4, "fx: -");
  ASSERT_TRUE(WriteStringToFile(dir + "/rig.yaml", broken).ok());
  auto reader = DatasetReader::Open(dir);
  ASSERT_FALSE(reader.ok());
  EXPECT_NE(reader.status().message().find("fx"), std::string::npos) << reader.status().message();
  EXPECT_NE(reader.status().message().find("rig.yaml"), std::string::npos) << reader.status().message();
}

TEST(CaptureSiteTest, MaskSourceNames) {
  for (const char* n : {"segment", "truth", "dataset", "none"}) {
    auto m = ParseMaskSource(n);
    ASSERT_TRUE(m.ok());
    EXPECT_STREQ(MaskSourceName(*m), n);
  }
  EXPECT_FALSE(ParseMaskSource("magic").ok());
}

}  // namespace
}  // namespace holo
