#include "studio/studio.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "studio/workloads.h"

namespace holo {
namespace {

Rig SmallRig(double scale = 0.25) {
  auto rig = LoadRig(ShippedRigPath("studio-8"));
  HOLO_CHECK_MSG(rig.ok(), rig.status().ToString());
  return rig->Scaled(scale);  // 160x120
}

// One pod at `eye` looking at `target`.
Rig OnePodRig(const Eigen::Vector3f& eye, const Eigen::Vector3f& target, const Eigen::Vector3f& up,
              int width = 320, int height = 240) {
  Rig rig;
  rig.name = "one";
  PodCalibration pod;
  pod.id = 0;
  pod.name = "pod0";
  pod.depth = pod.color = Intrinsics::FromFov(width, height, 60.0);
  pod.world_from_depth = LookAt(eye, target, up);
  rig.pods.push_back(pod);
  return rig;
}

std::unique_ptr<SyntheticStudio> Make(Rig rig, StudioOptions options) {
  auto s = SyntheticStudio::Create(std::move(rig), options);
  HOLO_CHECK_MSG(s.ok(), s.status().ToString());
  return std::move(s).value();
}

TEST(StudioTest, SameSeedGivesIdenticalFramesForAnyThreadCount) {
  StudioOptions o;
  o.num_figures = 2;
  o.num_props = 2;
  o.threads = 1;
  auto a = Make(SmallRig(), o);
  o.threads = 2;
  auto b = Make(SmallRig(), o);
  o.threads = 3;
  auto c = Make(SmallRig(), o);
  RgbdFrameSet fa, fb, fc, fa2;
  a->RenderFrame(7, &fa, nullptr);
  b->RenderFrame(7, &fb, nullptr);
  c->RenderFrame(7, &fc, nullptr);
  a->RenderFrame(3, &fa2, nullptr);
  a->RenderFrame(7, &fa2, nullptr);  // reused buffers, other frame in between
  ASSERT_EQ(fa.frames.size(), 8u);
  for (size_t i = 0; i < fa.frames.size(); ++i) {
    EXPECT_TRUE(fa.frames[i].color == fb.frames[i].color) << i;
    EXPECT_TRUE(fa.frames[i].depth == fb.frames[i].depth) << i;
    EXPECT_TRUE(fa.frames[i].color == fc.frames[i].color) << i;
    EXPECT_TRUE(fa.frames[i].depth == fc.frames[i].depth) << i;
    EXPECT_TRUE(fa.frames[i].color == fa2.frames[i].color) << i;
    EXPECT_TRUE(fa.frames[i].depth == fa2.frames[i].depth) << i;
    EXPECT_EQ(fa.frames[i].pod_id, static_cast<int>(i));
    EXPECT_EQ(fa.frames[i].timestamp_us, 233333);
    EXPECT_EQ(fa.frames[i].color.width(), 160);
    EXPECT_EQ(fa.frames[i].depth.height(), 120);
  }
}

TEST(StudioTest, RenderPodGivesThatPodsFrameOfRenderFrame) {
  StudioOptions o;
  o.threads = 2;
  auto a = Make(SmallRig(), o);
  auto b = Make(SmallRig(), o);
  RgbdFrameSet all;
  a->RenderFrame(5, &all, nullptr);
  for (int p : {0, 3, 7}) {
    RgbdFrame one;
    b->RenderPod(5, p, &one);
    EXPECT_TRUE(one.color == all.frames[static_cast<size_t>(p)].color) << p;
    EXPECT_TRUE(one.depth == all.frames[static_cast<size_t>(p)].depth) << p;
    EXPECT_EQ(one.pod_id, p);
    EXPECT_EQ(one.timestamp_us, all.frames[static_cast<size_t>(p)].timestamp_us);
  }
}

TEST(StudioTest, DifferentSeedGivesDifferentNoise) {
  StudioOptions o;
  auto a = Make(SmallRig(), o);
  o.seed = 2;
  auto b = Make(SmallRig(), o);
  RgbdFrameSet fa, fb;
  a->RenderFrame(0, &fa, nullptr);
  b->RenderFrame(0, &fb, nullptr);
  EXPECT_FALSE(fa.frames[0].depth == fb.frames[0].depth);
  EXPECT_FALSE(fa.frames[0].color == fb.frames[0].color);  // colour variation differs per seed
  // Noise also differs from frame to frame.
  a->RenderFrame(1, &fb, nullptr);
  int same = 0, valid = 0;
  for (size_t p = 0; p < fa.frames[2].depth.num_pixels(); ++p) {
    const uint16_t d0 = fa.frames[2].depth.data()[p], d1 = fb.frames[2].depth.data()[p];
    if (d0 && d1) ++valid, same += d0 == d1;
  }
  EXPECT_LT(same, valid * 0.5);
}

// σ of (noisy - true) on a fronto-parallel floor seen from `height`.
double MeasuredSigmaMm(float height) {
  StudioOptions o;
  o.empty_room = true;
  auto s = Make(OnePodRig({0, 0, height}, {0, 0, 0}, Eigen::Vector3f::UnitX()), o);
  RgbdFrameSet f;
  StudioGroundTruth gt;
  s->RenderFrame(0, &f, &gt);
  double sum = 0, sum2 = 0;
  int n = 0, dropped = 0;
  for (size_t p = 0; p < f.frames[0].depth.num_pixels(); ++p) {
    const int d = f.frames[0].depth.data()[p], t = gt.depth[0].data()[p];
    EXPECT_NEAR(t, height * 1000.0f, 1.0f);
    if (d == 0) {
      ++dropped;
      continue;
    }
    sum += d - t;
    sum2 += static_cast<double>(d - t) * (d - t);
    ++n;
  }
  // Only speckle dropouts on a frontal plane (0.2 %).
  EXPECT_LT(dropped, 0.01 * f.frames[0].depth.num_pixels());
  EXPECT_GT(dropped, 0);
  const double mean = sum / n;
  EXPECT_NEAR(mean, 0.0, 0.2);
  return std::sqrt(sum2 / n - mean * mean);
}

TEST(StudioTest, AxialNoiseGrowsWithDepthSquared) {
  const double s1 = MeasuredSigmaMm(1.0f), s15 = MeasuredSigmaMm(1.5f);
  EXPECT_NEAR(s1, 3.0, 0.6);
  EXPECT_NEAR(s15, 6.75, 6.75 * 0.2);
}

TEST(StudioTest, NoiseOffGivesTruthAndGrazingSurfacesDropOut) {
  StudioOptions o;
  o.depth_noise = false;
  auto s = Make(SmallRig(), o);
  RgbdFrameSet f;
  StudioGroundTruth gt;
  s->RenderFrame(4, &f, &gt);
  for (size_t i = 0; i < f.frames.size(); ++i) EXPECT_TRUE(f.frames[i].depth == gt.depth[i]);

  // A camera low over the floor sees it at grazing angles: far floor drops out.
  StudioOptions on;
  on.empty_room = true;
  auto low = Make(OnePodRig({0, 0, 0.3f}, {2, 0, 0.15f}, Eigen::Vector3f::UnitZ()), on);
  s = nullptr;
  low->RenderFrame(0, &f, &gt);
  const int W = f.frames[0].depth.width();
  const CameraModel cam = low->rig().pods[0].DepthCamera();
  int floor_far = 0, dropped = 0;
  for (int y = 0; y < f.frames[0].depth.height(); ++y)
    for (int x = 0; x < W; ++x) {
      const Eigen::Vector3f p = cam.UnprojectWorld(Eigen::Vector2f(x, y), gt.depth[0].at(x, y) * 0.001f);
      // Floor points more than 2.2 m away are seen at > 82° from the normal.
      if (std::abs(p.z()) < 0.01f && p.head<2>().norm() > 2.2f) {
        ++floor_far;
        dropped += f.frames[0].depth.at(x, y) == 0;
      }
    }
  ASSERT_GT(floor_far, 100);
  EXPECT_GT(dropped, 0.95 * floor_far);
}

// Distance from `p` to triangle abc.
float PointTriangleDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                           const Eigen::Vector3f& c) {
  const Eigen::Vector3f n = (b - a).cross(c - a);
  const float nn = n.squaredNorm();
  if (nn > 1e-20f) {
    const Eigen::Vector3f q = p - n * ((p - a).dot(n) / nn);
    const bool inside = (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 &&
                        (a - c).cross(q - c).dot(n) >= 0;
    if (inside) return (p - q).norm();
  }
  auto seg = [&](const Eigen::Vector3f& u, const Eigen::Vector3f& v) {
    const Eigen::Vector3f d = v - u;
    const float t = std::clamp((p - u).dot(d) / std::max(d.squaredNorm(), 1e-20f), 0.0f, 1.0f);
    return (p - (u + t * d)).norm();
  };
  return std::min({seg(a, b), seg(b, c), seg(c, a)});
}

TEST(StudioTest, GroundTruthDepthLiesOnGroundTruthMesh) {
  StudioOptions o;
  o.num_props = 2;
  const Rig rig = SmallRig(0.5);
  auto s = Make(rig, o);
  RgbdFrameSet f;
  StudioGroundTruth gt;
  s->RenderFrame(12, &f, &gt);
  ASSERT_TRUE(gt.foreground_mesh.Validate().ok());
  ASSERT_EQ(gt.foreground_mesh.normals.size(), gt.foreground_mesh.num_vertices());
  ASSERT_EQ(gt.foreground_mesh.colors.size(), gt.foreground_mesh.num_vertices());
  const Mesh& m = gt.foreground_mesh;
  for (int pod : {0, 3, 6}) {
    const CameraModel cam = rig.pods[pod].DepthCamera();
    std::vector<float> dist;
    int k = 0;
    for (int y = 0; y < gt.mask[pod].height(); ++y)
      for (int x = 0; x < gt.mask[pod].width(); ++x) {
        if (!gt.mask[pod].at(x, y) || (k++ % 23) != 0) continue;
        const Eigen::Vector3f p =
            cam.UnprojectWorld(Eigen::Vector2f(x, y), gt.depth[pod].at(x, y) * 0.001f);
        float best = 1e9f;
        for (const auto& t : m.triangles)
          best = std::min(best, PointTriangleDistance(p, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
        dist.push_back(best);
      }
    ASSERT_GT(dist.size(), 50u) << pod;
    std::nth_element(dist.begin(), dist.begin() + dist.size() / 2, dist.end());
    EXPECT_LT(dist[dist.size() / 2], 0.003f) << pod;
    EXPECT_LT(*std::max_element(dist.begin(), dist.end()), 0.02f) << pod;
  }
}

TEST(StudioTest, MaskIsWhereTheForegroundIs) {
  StudioOptions o;
  o.depth_noise = false;
  auto s = Make(SmallRig(), o);
  o.empty_room = true;
  auto room = Make(SmallRig(), o);
  RgbdFrameSet f, fr;
  StudioGroundTruth gt, gtr;
  s->RenderFrame(20, &f, &gt);
  room->RenderFrame(20, &fr, &gtr);
  for (size_t i = 0; i < f.frames.size(); ++i) {
    int fg = 0, in_front = 0;
    for (size_t p = 0; p < gt.mask[i].num_pixels(); ++p) {
      EXPECT_EQ(gtr.mask[i].data()[p], 0);
      const uint16_t d = gt.depth[i].data()[p], bg = gtr.depth[i].data()[p];
      if (gt.mask[i].data()[p]) {
        ++fg;
        in_front += d > 0 && d + 5 < bg;
      } else {
        EXPECT_EQ(d, bg);  // background pixels show the room
      }
    }
    EXPECT_GT(fg, 500) << i;  // a person is visible from every pod
    EXPECT_GT(in_front, 0.97 * fg) << i;
  }
  EXPECT_TRUE(gtr.foreground_mesh.empty());
}

TEST(StudioTest, ForegroundMeshKeepsTopologyAndMoves) {
  StudioOptions o;
  o.num_figures = 2;
  o.num_props = 2;
  auto s = Make(SmallRig(), o);
  const Mesh a = s->ForegroundMesh(0), b = s->ForegroundMesh(15);
  ASSERT_GT(a.num_triangles(), 10000u);
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.colors, b.colors);
  int moved = 0;
  float max_step = 0;
  const Mesh c = s->ForegroundMesh(16);
  for (size_t i = 0; i < a.num_vertices(); ++i) {
    moved += (a.positions[i] - b.positions[i]).norm() > 0.005f;
    max_step = std::max(max_step, (b.positions[i] - c.positions[i]).norm());
  }
  EXPECT_GT(moved, static_cast<int>(a.num_vertices() / 4));
  EXPECT_LT(max_step, 0.15f);  // smooth motion: < 15 cm per frame anywhere
  // A person is about 1.75 m tall and stands on the floor.
  float zmin = 1e9f, zmax = -1e9f;
  for (const auto& p : a.positions) zmin = std::min(zmin, p.z()), zmax = std::max(zmax, p.z());
  EXPECT_GT(zmax, 1.7f);
  EXPECT_LT(zmax, 1.95f);
  EXPECT_GT(zmin, -0.01f);
}

TEST(StudioTest, FigureCastsAShadowOnTheFloor) {
  StudioOptions o;
  auto s = Make(SmallRig(), o);
  o.empty_room = true;
  auto room = Make(SmallRig(), o);
  CameraModel top;
  top.intrinsics = Intrinsics::FromFov(200, 200, 90);
  top.world_from_camera = LookAt({0, 0, 2.9f}, {0, 0, 0}, Eigen::Vector3f::UnitX());
  ImageRgb8 c, cr;
  ImageGray8 m;
  s->RenderView(10, top, &c, nullptr, &m);
  room->RenderView(10, top, &cr, nullptr, nullptr);
  int darker = 0, brighter = 0;
  for (size_t p = 0; p < m.num_pixels(); ++p) {
    if (m.data()[p]) continue;
    const int lum = c.data()[3 * p] + c.data()[3 * p + 1] + c.data()[3 * p + 2];
    const int lum_room = cr.data()[3 * p] + cr.data()[3 * p + 1] + cr.data()[3 * p + 2];
    darker += lum < 0.7 * lum_room;
    brighter += lum > lum_room;
  }
  EXPECT_GT(darker, 300);  // the figure's shadow
  EXPECT_EQ(brighter, 0);
}

TEST(StudioTest, RenderViewFromAPodEqualsItsTruth) {
  auto s = Make(SmallRig(), StudioOptions{});
  RgbdFrameSet f;
  StudioGroundTruth gt;
  s->RenderFrame(9, &f, &gt);
  for (int pod : {1, 5}) {
    ImageDepth16 d;
    ImageGray8 m;
    ImageRgb8 c;
    s->RenderView(9, s->rig().pods[pod].DepthCamera(), &c, &d, &m);
    EXPECT_TRUE(d == gt.depth[pod]);
    EXPECT_TRUE(m == gt.mask[pod]);
    EXPECT_EQ(c.width(), 160);
  }
}

TEST(StudioTest, DistortedAndUnregisteredCameras) {
  Rig rig = SmallRig(0.5);
  rig.pods.resize(2);
  rig.pods[0].depth.distortion = {-0.2, 0.05, 0.001, -0.001, 0};
  rig.pods[0].color = rig.pods[0].depth;
  rig.pods[1].color = rig.pods[1].color.Scaled(1.5);  // 480x360 colour, 320x240 depth
  rig.pods[1].color_from_depth = Eigen::Translation3f(0.025f, 0, 0) * Pose::Identity();
  StudioOptions o;
  o.depth_noise = false;
  auto s = Make(rig, o);
  RgbdFrameSet f;
  StudioGroundTruth gt;
  s->RenderFrame(3, &f, &gt);
  EXPECT_EQ(f.frames[1].color.width(), 480);
  EXPECT_EQ(f.frames[1].depth.width(), 320);
  // Every valid distorted pixel unprojects onto the scene seen by an undistorted camera.
  CameraModel pin = rig.pods[0].DepthCamera();
  pin.intrinsics.distortion = {0, 0, 0, 0, 0};
  ImageDepth16 d;
  s->RenderView(3, pin, nullptr, &d, nullptr);
  const CameraModel cam = rig.pods[0].DepthCamera();
  int checked = 0, agree = 0;
  for (int y = 0; y < 240; y += 7)
    for (int x = 0; x < 320; x += 7) {
      const uint16_t z = f.frames[0].depth.at(x, y);
      ASSERT_GT(z, 0);
      Eigen::Vector2f px;
      ASSERT_TRUE(pin.ProjectWorld(cam.UnprojectWorld(Eigen::Vector2f(x, y), z * 0.001f), &px));
      const int ix = static_cast<int>(std::lround(px.x())), iy = static_cast<int>(std::lround(px.y()));
      if (!d.Contains(ix, iy)) continue;
      ++checked;
      // Nearest-neighbour resampling: z must lie within the depths around the
      // projected position (steep on the far floor).
      int lo = 65535, hi = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (d.Contains(ix + dx, iy + dy)) lo = std::min<int>(lo, d.at(ix + dx, iy + dy)), hi = std::max<int>(hi, d.at(ix + dx, iy + dy));
      agree += z + 10 >= lo && z <= hi + 10;
    }
  ASSERT_GT(checked, 500);
  EXPECT_GT(agree, 0.95 * checked);
}

TEST(StudioTest, CreateRejectsBadOptions) {
  StudioOptions o;
  o.num_figures = 3;
  auto s = SyntheticStudio::Create(SmallRig(), o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("num_figures"), std::string::npos) << s.status().message();
  o = StudioOptions{};
  o.noise.sigma_at_1m_mm = -1;
  s = SyntheticStudio::Create(SmallRig(), o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("sigma_at_1m_mm"), std::string::npos);
  o = StudioOptions{};
  o.fps = 0;
  EXPECT_FALSE(SyntheticStudio::Create(SmallRig(), o).ok());
  o = StudioOptions{};
  o.noise.flying_pixel_prob = 1.5f;
  EXPECT_FALSE(SyntheticStudio::Create(SmallRig(), o).ok());
  Rig empty;
  empty.name = "empty";
  EXPECT_FALSE(SyntheticStudio::Create(empty, StudioOptions{}).ok());
  Rig bad = SmallRig();
  bad.pods[0].depth.fx = -1;
  EXPECT_FALSE(SyntheticStudio::Create(bad, StudioOptions{}).ok());
}

TEST(StudioTest, FrameSourceAndWorkloads) {
  auto s = Make(SmallRig(), StudioOptions{});
  RgbdFrameSet f;
  ASSERT_TRUE(s->Next(&f).ok());
  EXPECT_EQ(f.frame_index, 0);
  ASSERT_TRUE(s->Seek(30).ok());
  ASSERT_TRUE(s->Next(&f).ok());
  EXPECT_EQ(f.frame_index, 30);
  EXPECT_EQ(f.frames[0].timestamp_us, 1000000);
  EXPECT_EQ(s->Seek(-1).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(s->num_frames(), -1);

  auto q = GetWorkload("S8-QVGA");
  ASSERT_TRUE(q.ok()) << q.status().ToString();
  EXPECT_EQ(q->rig.pods.size(), 8u);
  EXPECT_EQ(q->rig.pods[0].depth.width, 320);
  EXPECT_EQ(q->studio.num_figures, 1);
  EXPECT_FLOAT_EQ(q->voxel_size_m, 0.008f);
  auto v = GetWorkload("S8-VGA");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->rig.pods[0].color.height, 480);
  EXPECT_EQ(v->studio.num_figures, 2);
  EXPECT_EQ(v->studio.seed, 2u);
  // The stream mesh's budget: 10 k triangles per person.
  EXPECT_EQ(q->stream_triangles, 10000u);
  EXPECT_EQ(v->stream_triangles, 20000u);
  EXPECT_EQ(GetWorkload("nope").status().code(), StatusCode::kNotFound);
  for (const auto& name : WorkloadNames()) EXPECT_TRUE(GetWorkload(name).ok()) << name;
}

}  // namespace
}  // namespace holo
