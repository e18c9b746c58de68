// The pipeline test at full size: 100 frames of S8-QVGA through the
// concurrent pipeline — none lost, order kept, results identical to running
// the stages serially. Slow (labelled "slow").
#include <gtest/gtest.h>

#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

std::vector<std::pair<int64_t, uint64_t>> RunS8Qvga(bool serial, bool temporal = false, int frames = 100,
                                                    std::vector<size_t>* triangles = nullptr) {
  auto wl = GetWorkload("S8-QVGA");
  HOLO_CHECK(wl.ok());
  SyntheticStudio studio(wl->rig, wl->studio);
  StudioOptions eo = wl->studio;
  eo.empty_room = true;
  SyntheticStudio empty(wl->rig, eo);
  CaptureSiteOptions o;
  o.tsdf.voxel_size = wl->voxel_size_m;
  o.pipeline.serial = serial;
  o.pipeline.max_frames = frames;
  o.temporal = temporal;
  auto site = CaptureSite::Create(&studio, &empty, nullptr, o);
  HOLO_CHECK(site.ok());
  std::vector<std::pair<int64_t, uint64_t>> out;
  auto stats = (*site)->Run([&](const FrameWork& w) {
    // A fingerprint of the whole mesh: positions, triangles and colours.
    uint64_t h = 1469598103934665603ull;
    auto mix = [&h](const void* p, size_t n) {
      const auto* b = static_cast<const uint8_t*>(p);
      for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
    };
    mix(w.mesh.positions.data(), w.mesh.positions.size() * sizeof(Eigen::Vector3f));
    mix(w.mesh.triangles.data(), w.mesh.triangles.size() * sizeof(w.mesh.triangles[0]));
    mix(w.mesh.colors.data(), w.mesh.colors.size() * 3);
    out.push_back({w.frames.frame_index, h});
    if (triangles) triangles->push_back(w.mesh.triangles.size());
    return OkStatus();
  });
  EXPECT_TRUE(stats.ok()) << stats.status().ToString();
  return out;
}

TEST(CaptureSiteSlowTest, HundredFramesOfS8QvgaConcurrentEqualsSerial) {
  const auto serial = RunS8Qvga(true);
  const auto concurrent = RunS8Qvga(false);
  ASSERT_EQ(concurrent.size(), 100u);
  for (size_t i = 0; i < concurrent.size(); ++i) EXPECT_EQ(concurrent[i].first, static_cast<int64_t>(i));
  EXPECT_EQ(serial, concurrent);
}

// The capture site with temporal fusion (holoport-server --temporal): 20
// frames of S8-QVGA, every frame a mesh, concurrent = serial.
TEST(CaptureSiteSlowTest, TemporalFusionOnS8QvgaConcurrentEqualsSerial) {
  std::vector<size_t> tris;
  const auto serial = RunS8Qvga(true, true, 20, &tris);
  const auto concurrent = RunS8Qvga(false, true, 20);
  ASSERT_EQ(concurrent.size(), 20u);
  ASSERT_EQ(tris.size(), 20u);
  for (size_t i = 0; i < concurrent.size(); ++i) {
    EXPECT_EQ(concurrent[i].first, static_cast<int64_t>(i));
    EXPECT_GT(tris[i], 5000u) << "frame " << i;
  }
  EXPECT_EQ(serial, concurrent);
}

}  // namespace
}  // namespace holo
