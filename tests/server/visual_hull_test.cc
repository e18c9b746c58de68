// The visual hull (server/fusion/visual_hull.h): the silhouettes of a known
// shape seen from known cameras carve a closed surface that contains the
// shape and stays within a stated bound of it; bad input is refused.
#include "server/fusion/visual_hull.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <utility>

#include <gtest/gtest.h>

#include "analytic_scenes.h"
#include "common/mesh.h"

namespace holo {
namespace {

// A ring of 8 pods around the object plus one above and one below it, so
// that every side of it is seen; masks from the exact depth.
Rig TenPods(const Eigen::Vector3f& centre) {
  Rig rig = RingRig(8, centre, 1.5f, 240, 180);
  for (float dz : {1.4f, -1.4f}) {
    PodCalibration pod = rig.pods[0];
    pod.id = static_cast<int>(rig.pods.size());
    pod.name = "cam" + std::to_string(pod.id);
    pod.world_from_depth = LookAt(centre + Eigen::Vector3f(0.3f, 0.2f, dz), centre);
    rig.pods.push_back(pod);
  }
  return rig;
}

RgbdFrameSet WithMasks(RgbdFrameSet fs) {
  for (RgbdFrame& f : fs.frames) {
    f.mask.Resize(f.depth.width(), f.depth.height());
    for (size_t i = 0; i < f.depth.num_pixels(); ++i) f.mask.data()[i] = f.depth.data()[i] > 0 ? 255 : 0;
  }
  return fs;
}

TsdfOptions Volume(float voxel) {
  TsdfOptions o;
  o.voxel_size = voxel;
  o.truncation_voxels = 3;
  o.integrate_color = false;
  o.threads = 2;
  return o;
}

size_t IrregularEdges(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> edges;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k], b = t[(k + 1) % 3];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  size_t bad = 0;
  for (const auto& [e, n] : edges) bad += n != 2;
  return bad;
}

TEST(VisualHull, SphereHullIsClosedContainsTheSphereAndStaysNearIt) {
  const Eigen::Vector3f c(0.02f, -0.03f, 1.0f);
  const float r = 0.35f, voxel = 0.016f;
  const Rig rig = TenPods(c);
  const RgbdFrameSet fs = WithMasks(RenderAnalytic(rig, Sphere(c, r)));
  VisualHullOptions ho;
  ho.box_min = c - Eigen::Vector3f::Constant(0.8f);
  ho.box_max = c + Eigen::Vector3f::Constant(0.8f);
  VisualHull hull(ho);
  TsdfVolume volume(Volume(voxel));
  ASSERT_TRUE(hull.Build(rig, fs, &volume).ok());
  EXPECT_GT(hull.stats().blocks_filled, 0u);
  EXPECT_LT(hull.stats().blocks_filled, hull.stats().blocks_tested / 2) << "only blocks near the surface are filled";
  Mesh mesh;
  volume.ExtractMesh(&mesh);
  ASSERT_GT(mesh.num_triangles(), 1000u);
  EXPECT_EQ(IrregularEdges(mesh), 0u) << "a closed surface (no block near it was skipped)";
  // The hull contains the sphere (up to the voxel grid) and, seen from ten
  // directions, bulges out by at most ~11 % of the radius (between views).
  double sum = 0, rmin = 1e9, rmax = 0;
  for (const Eigen::Vector3f& p : mesh.positions) {
    const double d = (p - c).norm();
    sum += d;
    rmin = std::min(rmin, d);
    rmax = std::max(rmax, d);
  }
  const double mean = sum / static_cast<double>(mesh.positions.size());
  std::printf("sphere r %.0f mm from 10 pods: hull radius min %.1f mean %.1f max %.1f mm, %zu triangles, %zu of %zu blocks\n",
              r * 1e3, rmin * 1e3, mean * 1e3, rmax * 1e3, mesh.num_triangles(), hull.stats().blocks_filled,
              hull.stats().blocks_tested);
  EXPECT_GT(rmin, r - voxel) << "the hull never cuts into the object";
  EXPECT_LT(rmax, 1.11 * r + voxel);
  EXPECT_LT(mean, 1.05 * r) << "mean radius " << mean;
  EXPECT_GT(mean, r - 0.5 * voxel);
}

TEST(VisualHull, BoxHullMatchesTheBoxFacesItSees) {
  // A box's silhouettes from a ring: its vertical faces are carved exactly
  // (each is a silhouette edge in some view); mean distance to the box small.
  const Eigen::Vector3f lo(-0.2f, -0.15f, 0.7f), hi(0.25f, 0.2f, 1.3f);
  const Eigen::Vector3f c = 0.5f * (lo + hi);
  const Rig rig = TenPods(c);
  const RgbdFrameSet fs = WithMasks(RenderAnalytic(rig, Box(lo, hi)));
  VisualHullOptions ho;
  ho.box_min = c - Eigen::Vector3f::Constant(0.8f);
  ho.box_max = c + Eigen::Vector3f::Constant(0.8f);
  VisualHull hull(ho);
  TsdfVolume volume(Volume(0.01f));
  ASSERT_TRUE(hull.Build(rig, fs, &volume).ok());
  Mesh mesh;
  volume.ExtractMesh(&mesh);
  ASSERT_GT(mesh.num_triangles(), 1000u);
  double sum = 0;
  for (const Eigen::Vector3f& p : mesh.positions) {
    // Distance to the box surface (outside: to the box; inside: to the nearest face).
    const Eigen::Vector3f q = p.cwiseMax(lo).cwiseMin(hi);
    double d = (p - q).norm();
    if (d == 0) d = std::min({p.x() - lo.x(), hi.x() - p.x(), p.y() - lo.y(), hi.y() - p.y(), p.z() - lo.z(), hi.z() - p.z()});
    sum += d;
  }
  const double mean = sum / static_cast<double>(mesh.positions.size());
  std::printf("box hull: mean distance to the box %.1f mm, %zu triangles\n", mean * 1e3, mesh.num_triangles());
  EXPECT_LT(mean, 0.02) << "mean distance to the box, m";
}

TEST(VisualHull, RefusesFramesThatDoNotFitTheRig) {
  const Eigen::Vector3f c(0, 0, 1);
  const Rig rig = TenPods(c);
  RgbdFrameSet fs = WithMasks(RenderAnalytic(rig, Sphere(c, 0.3f)));
  VisualHull hull(VisualHullOptions{});
  TsdfVolume volume(Volume(0.02f));
  RgbdFrameSet missing = fs;
  missing.frames[3].mask = ImageGray8();
  Status st = hull.Build(rig, missing, &volume);
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.ToString().find("pod 3 has no mask"), std::string::npos) << st.ToString();
  RgbdFrameSet small = fs;
  small.frames[2].mask.Resize(10, 10);
  st = hull.Build(rig, small, &volume);
  EXPECT_NE(st.ToString().find("pod 2 mask is 10x10"), std::string::npos) << st.ToString();
  RgbdFrameSet fewer = fs;
  fewer.frames.pop_back();
  EXPECT_FALSE(hull.Build(rig, fewer, &volume).ok());
  EXPECT_FALSE(hull.Build(rig, fs, nullptr).ok());
  VisualHullOptions bad;
  bad.box_max.z() = bad.box_min.z();
  EXPECT_FALSE(VisualHull::Create(bad).ok());
  bad = VisualHullOptions{};
  bad.min_views = 0;
  EXPECT_FALSE(VisualHull::Create(bad).ok());
}

TEST(VisualHull, TooFewViewsLeaveTheVolumeEmpty) {
  // Every point is seen by at most 10 pods; asking for more leaves nothing
  // observed, so no surface (rather than an unbounded hull).
  const Eigen::Vector3f c(0, 0, 1);
  const Rig rig = TenPods(c);
  const RgbdFrameSet fs = WithMasks(RenderAnalytic(rig, Sphere(c, 0.3f)));
  VisualHullOptions ho;
  ho.min_views = 11;
  VisualHull hull(ho);
  TsdfVolume volume(Volume(0.02f));
  ASSERT_TRUE(hull.Build(rig, fs, &volume).ok());
  Mesh mesh;
  volume.ExtractMesh(&mesh);
  EXPECT_EQ(mesh.num_triangles(), 0u);
}

}  // namespace
}  // namespace holo
