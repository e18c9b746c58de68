// Offloaded rendering, simulated end to end (render host → RenderedFrame →
// thin client): reprojection beats the stale image on a rotating head,
// prediction improves on that for smooth motion, an enlarged FOV removes the
// black border. Small renders; no timing.
#include <cmath>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "client/pose/head_pose.h"
#include "client/reproject/offload_sim.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::reproject {
namespace {

constexpr double kDeg = M_PI / 180.0;

// 90 Hz samples of an eye 2.6 m from the studio's centre, looking at it,
// yawing by `yaw_deg(t)` and pitching down 8°.
template <typename YawFn>
std::vector<pose::PoseSample> Trace(YawFn yaw_deg, double seconds) {
  std::vector<pose::PoseSample> out;
  for (int i = 0; i <= static_cast<int>(seconds * 90); ++i) {
    pose::PoseSample s;
    s.time_us = std::llround(i / 90.0 * 1e6);
    const double t = s.time_us * 1e-6;
    s.position = Eigen::Vector3d(-2.6, 0.01 * std::sin(2 * t), 1.65);
    s.rotation = pose::RotationFromYawPitchRoll(yaw_deg(t) * kDeg, -8 * kDeg, 0);
    out.push_back(s);
  }
  return out;
}

class OffloadTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto w = GetWorkload("S8-QVGA");
    ASSERT_TRUE(w.ok());
    StudioOptions so = w->studio;
    so.threads = 2;
    studio_ = std::move(SyntheticStudio::Create(w->rig, so).value());
    options_.width = 256;
    options_.height = 144;
    options_.hfov_deg = 80;
    options_.latencies_ms = {60};
    options_.display_frames = 12;
    options_.warmup_s = 0.5;
  }
  // The whole studio (room included): it fills the frame, so a black
  // border costs what it costs a viewer.
  SceneAtFrame StudioScene() {
    return [this](int64_t frame) -> SceneRenderFn {
      return [this, frame](const CameraModel& cam, ImageRgb8* c, ImageDepth16* d, ImageGray8* m) {
        studio_->RenderView(frame, cam, c, d, nullptr);
        if (m) m->Resize(cam.intrinsics.width, cam.intrinsics.height, 255);
        return OkStatus();
      };
    };
  }
  SceneAtFrame ForegroundScene() {
    return [this](int64_t frame) -> SceneRenderFn {
      if (frame != mesh_frame_) {
        mesh_ = studio_->ForegroundMesh(frame);
        mesh_frame_ = frame;
      }
      return MeshSceneRenderer(mesh_);
    };
  }
  std::map<OffloadMode, OffloadResult> Run(const std::vector<pose::PoseSample>& trace, const SceneAtFrame& scene) {
    auto r = SimulateOffload(trace, scene, options_);
    HOLO_CHECK_MSG(r.ok(), r.status().ToString());
    std::map<OffloadMode, OffloadResult> out;
    for (const OffloadResult& x : *r) out[x.mode] = x;
    return out;
  }

  std::unique_ptr<SyntheticStudio> studio_;
  Mesh mesh_;
  int64_t mesh_frame_ = -1;
  OffloadSimOptions options_;
};

TEST_F(OffloadTest, ReprojectionBeatsTheStaleImageOnARotatingHead) {
  // Turning steadily at 50°/s: 3° off after 60 ms.
  const auto trace = Trace([](double t) { return -25 + 50 * t; }, 1.5);
  for (const auto& [name, scene] : {std::make_pair("foreground", ForegroundScene()),
                                    std::make_pair("studio", StudioScene())}) {
    for (ReprojectMethod method : {ReprojectMethod::kRotation, ReprojectMethod::kPlane, ReprojectMethod::kDepth}) {
      options_.method = method;
      auto r = Run(trace, scene);
      EXPECT_EQ(r[OffloadMode::kStale].frames, options_.display_frames);
      // On black, the border costs little and the gain is large; in the
      // room the border (no source there) eats much of the gain.
      const double gain_db = std::string(name) == "foreground" ? 3.0 : 0.5;
      EXPECT_GT(r[OffloadMode::kReprojected].psnr_content_db, r[OffloadMode::kStale].psnr_content_db + gain_db)
          << name << " " << ReprojectMethodName(method);
      EXPECT_GT(r[OffloadMode::kReprojected].psnr_db, r[OffloadMode::kStale].psnr_db)
          << name << " " << ReprojectMethodName(method);
      // Nothing beats rendering at the true pose.
      EXPECT_GT(r[OffloadMode::kIdeal].psnr_db, r[OffloadMode::kReprojected].psnr_db) << name;
      EXPECT_EQ(r[OffloadMode::kStale].black_border_fraction, 0.0);
      EXPECT_GT(r[OffloadMode::kReprojected].black_border_fraction, 0.01) << name;
    }
  }
}

TEST_F(OffloadTest, PredictionImprovesFurtherOnASmoothTrace) {
  // Smooth looking around: ±30° at 0.3 Hz (peak 57°/s).
  const auto trace = Trace([](double t) { return 30 * std::sin(2 * M_PI * 0.3 * t); }, 3.0);
  options_.display_frames = 16;
  auto r = Run(trace, StudioScene());
  EXPECT_GT(r[OffloadMode::kReprojected].psnr_db, r[OffloadMode::kStale].psnr_db);
  EXPECT_GT(r[OffloadMode::kPredicted].psnr_db, r[OffloadMode::kReprojected].psnr_db + 1.0);
  EXPECT_LT(r[OffloadMode::kPredicted].black_border_fraction, 0.5 * r[OffloadMode::kReprojected].black_border_fraction);
}

TEST_F(OffloadTest, EnlargedFovRemovesTheBlackBorder) {
  const auto trace = Trace([](double t) { return 30 * std::sin(2 * M_PI * 0.3 * t); }, 3.0);
  options_.margin = 0.2;
  options_.predictor = pose::PredictorModel::kNone;  // the border from the full latency
  auto r = Run(trace, StudioScene());
  EXPECT_GT(r[OffloadMode::kPredicted].black_border_fraction, 0.01);
  EXPECT_LT(r[OffloadMode::kEnlarged].black_border_fraction, 0.1 * r[OffloadMode::kPredicted].black_border_fraction);
  EXPECT_GT(r[OffloadMode::kEnlarged].psnr_db, r[OffloadMode::kPredicted].psnr_db + 1.0);
  // The enlarged image is bigger on the wire.
  EXPECT_GT(r[OffloadMode::kEnlarged].wire_bytes, r[OffloadMode::kPredicted].wire_bytes);
}

TEST_F(OffloadTest, RejectsBadOptions) {
  const auto trace = Trace([](double) { return 0.0; }, 1.0);
  options_.latencies_ms = {};
  EXPECT_FALSE(SimulateOffload(trace, StudioScene(), options_).ok());
  options_.latencies_ms = {50};
  options_.margin = -1;
  EXPECT_FALSE(SimulateOffload(trace, StudioScene(), options_).ok());
  options_.margin = 0.2;
  EXPECT_FALSE(SimulateOffload({trace[0]}, StudioScene(), options_).ok());
  options_.warmup_s = 5;  // longer than the trace
  EXPECT_FALSE(SimulateOffload(trace, StudioScene(), options_).ok());
}

}  // namespace
}  // namespace holo::reproject
