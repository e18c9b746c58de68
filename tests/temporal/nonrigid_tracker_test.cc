// Non-rigid tracking (server/temporal/): the ED graph and the tracker on
// noise-free renders of the studio's true foreground mesh.
#include "server/temporal/nonrigid_tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "common/metrics/triangle_index.h"
#include "server/fusion/mesh_cleanup.h"
#include "server/fusion/tsdf.h"
#include "server/temporal/deformation_graph.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/mesh_renderer.h"

namespace holo {
namespace {

using Eigen::Vector3f;

// Noise-free depth and exact masks of `mesh` from every pod.
RgbdFrameSet RenderSet(const Rig& rig, const Mesh& mesh) {
  RgbdFrameSet set;
  set.frames.resize(rig.pods.size());
  for (size_t k = 0; k < rig.pods.size(); ++k) {
    set.frames[k].pod_id = static_cast<int>(k);
    EXPECT_TRUE(RenderMesh(mesh, rig.pods[k].DepthCamera(), &set.frames[k].color, &set.frames[k].depth, &set.frames[k].mask).ok());
  }
  return set;
}

Mesh Transformed(const Mesh& m, const Eigen::Isometry3f& t) {
  Mesh out = m;
  for (auto& p : out.positions) p = t * p;
  for (auto& n : out.normals) n = t.linear() * n;
  return out;
}

struct Model {
  std::vector<Vector3f> points, normals;
  std::vector<size_t> vertex;  // mesh vertex of each point
};

// The model a temporal pipeline would track: the fused (outer) surface of
// `set`, 8 mm voxels, every `stride`-th vertex.
Model FusedModel(const Rig& rig, const RgbdFrameSet& set, size_t stride) {
  TsdfOptions o;
  o.voxel_size = 0.008f;
  o.threads = 2;
  o.depth_noise_at_1m_mm = 0;  // the depth is rendered from the true mesh: exact
  TsdfVolume vol(o);
  const Status s = vol.Integrate(rig, set);
  EXPECT_TRUE(s.ok()) << s.message();
  Mesh m;
  vol.ExtractMesh(&m);
  EXPECT_TRUE(CleanupMesh(MeshCleanupOptions{}, &m).ok());
  Model out;
  for (size_t i = 0; i < m.positions.size(); i += stride) {
    out.points.push_back(m.positions[i]);
    out.normals.push_back(m.normals[i].normalized());
    out.vertex.push_back(i);
  }
  return out;
}

class TrackerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto w = GetWorkload("S8-QVGA");
    ASSERT_TRUE(w.ok()) << w.status().message();
    rig_ = w->rig;
    StudioOptions so = w->studio;
    so.threads = 2;
    studio_ = std::make_unique<SyntheticStudio>(rig_, so);
  }
  Rig rig_;
  std::unique_ptr<SyntheticStudio> studio_;
};

TEST(DeformationGraphTest, BuildSkinAndWarp) {
  std::vector<Vector3f> pts;
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) pts.emplace_back(i * 0.01f, j * 0.01f, 0.0f);
  DeformationGraphOptions o;
  o.node_spacing_m = 0.1f;
  DeformationGraph g;
  ASSERT_TRUE(g.Build(pts, o).ok());
  EXPECT_EQ(g.num_nodes(), 16u);  // 4 × 4 cells
  for (size_t k = 0; k < g.num_nodes(); ++k) EXPECT_GE(g.neighbors(static_cast<int>(k)).size(), 2u);
  const SkinWeights s = g.Skin(Vector3f(0.2f, 0.2f, 0.0f));
  ASSERT_TRUE(s.valid());
  float sum = 0;
  for (float w : s.weight) sum += w;
  EXPECT_NEAR(sum, 1.0f, 1e-5f);
  // Identity warp; then a rigid global motion moves every point rigidly, also
  // after folding it into the nodes.
  EXPECT_LT((g.Warp(Vector3f(0.2f, 0.2f, 0), s) - Vector3f(0.2f, 0.2f, 0)).norm(), 1e-6f);
  Eigen::Isometry3f t = Eigen::Isometry3f::Identity();
  t.linear() = Eigen::AngleAxisf(0.3f, Vector3f(0.2f, 1, 0.1f).normalized()).toRotationMatrix();
  t.translation() = Vector3f(0.1f, -0.2f, 0.05f);
  g.global() = t;
  const Vector3f p(0.23f, 0.17f, 0.0f);
  const SkinWeights sp = g.Skin(p);
  EXPECT_LT((g.Warp(p, sp) - t * p).norm(), 1e-5f);
  g.FoldGlobalIntoNodes();
  EXPECT_LT((g.Warp(p, sp) - t * p).norm(), 1e-5f);
  Eigen::Matrix3f m;
  Vector3f c;
  g.BlendedTransform(sp, &m, &c);
  EXPECT_LT((m * p + c - t * p).norm(), 1e-5f);
  EXPECT_FALSE(g.Build(pts, DeformationGraphOptions{.node_spacing_m = -1}).ok());
}

// A known rigid motion (3° about a tilted axis, 25 mm) of the studio's figure
// and ball is recovered: rotation error < 1°, translation error < 2 mm.
void RigidRecovery(const Rig& rig, SyntheticStudio* studio, TrackerSolver solver) {
  const Mesh truth = studio->ForegroundMesh(0);
  ASSERT_FALSE(truth.normals.empty());
  Eigen::Isometry3f motion = Eigen::Isometry3f::Identity();
  const Vector3f centre(0, 0, 0.9f);
  motion.linear() = Eigen::AngleAxisf(3.0f * 3.14159265f / 180, Vector3f(0.3f, 0.2f, 1.0f).normalized()).toRotationMatrix();
  motion.translation() = centre - motion.linear() * centre + Vector3f(0.015f, -0.018f, 0.008f);
  const RgbdFrameSet set = RenderSet(rig, Transformed(truth, motion));
  const Model model = FusedModel(rig, RenderSet(rig, truth), 12);
  DeformationGraph graph;
  ASSERT_TRUE(graph.Build(model.points, DeformationGraphOptions{}).ok());
  TrackerOptions to;
  to.solver = solver;
  NonrigidTracker tracker(to);
  TrackResult res;
  ASSERT_TRUE(tracker.Track(rig, set, model.points, model.normals, &graph, &res).ok());
  // Fit a rigid transform to the warped points (Umeyama) and compare.
  Eigen::Matrix3Xd src(3, model.points.size()), dst(3, model.points.size());
  for (size_t i = 0; i < model.points.size(); ++i) {
    src.col(static_cast<Eigen::Index>(i)) = model.points[i].cast<double>();
    dst.col(static_cast<Eigen::Index>(i)) = graph.Warp(model.points[i], graph.Skin(model.points[i])).cast<double>();
  }
  const Eigen::Matrix4d fit = Eigen::umeyama(src, dst, false);
  Eigen::Isometry3f est(fit.cast<float>());
  const float rot_err_deg = Eigen::AngleAxisf(est.linear() * motion.linear().transpose()).angle() * 180 / 3.14159265f;
  // Translation error at the figure's centre.
  const float trans_err_mm = (est * centre - motion * centre).norm() * 1000;
  double mean_err = 0;
  for (size_t i = 0; i < model.points.size(); ++i)
    mean_err += (dst.col(static_cast<Eigen::Index>(i)).cast<float>() - motion * model.points[i]).norm();
  mean_err /= model.points.size();
  std::printf("[%s] rigid: rotation error %.3f deg, translation error %.3f mm, mean point error %.2f mm, "
              "%d nodes, %zu/%zu points associated, rms %.2f mm, failed nodes %d, track %.1f ms (rigid %.1f, assoc %.1f, solve %.1f, pcg it %d)\n",
              TrackerSolverName(solver), rot_err_deg, trans_err_mm, mean_err * 1000, static_cast<int>(graph.num_nodes()),
              res.associated_points, res.num_points, res.data_rms_m * 1000, res.failed_nodes, res.total_ms,
              res.rigid_ms, res.associate_ms, res.solve_ms, res.pcg_iterations);
  EXPECT_LT(rot_err_deg, 1.0f);
  EXPECT_LT(trans_err_mm, 2.0f);
  EXPECT_LT(mean_err, 0.004);
  EXPECT_LE(res.failed_nodes, static_cast<int>(graph.num_nodes()) / 100);
}

TEST_F(TrackerTest, RigidMotionRecoveredGaussNewton) { RigidRecovery(rig_, studio_.get(), TrackerSolver::kGaussNewtonPcg); }
TEST_F(TrackerTest, RigidMotionRecoveredCeres) { RigidRecovery(rig_, studio_.get(), TrackerSolver::kCeres); }

}  // namespace
}  // namespace holo

namespace holo {
namespace {

// The figure's largest smooth motion within the first 7 s (the wave of the
// right arm, walking legs) from one frame to the next (30 fps), tracked from
// the fused model of frame t into noise-free depth of frame t + 1. Bound:
// warped model points lie on average within 3 mm of the true surface of
// frame t + 1 (95th percentile 8 mm), and much closer than without tracking
// (measured: 1.7 / 4.5 mm after, 8.6 / 37 mm before, hand moving 10.5 cm).
TEST_F(TrackerTest, FigureBendTrackedWithinBound) {
  constexpr size_t kFigureVertices = 7696;  // the figure comes first in the truth mesh
  int best_t = 0;
  float best_motion = 0;
  for (int t = 0; t <= 200; t += 5) {
    const Mesh a = studio_->ForegroundMesh(t), b = studio_->ForegroundMesh(t + 1);
    float mx = 0;
    for (size_t i = 0; i < kFigureVertices; ++i) mx = std::max(mx, (a.positions[i] - b.positions[i]).norm());
    if (mx > best_motion) {
      best_motion = mx;
      best_t = t;
    }
  }
  const Mesh truth_a = studio_->ForegroundMesh(best_t), truth_b = studio_->ForegroundMesh(best_t + 1);
  const Model model = FusedModel(rig_, RenderSet(rig_, truth_a), 8);
  const RgbdFrameSet target = RenderSet(rig_, truth_b);
  auto index = metrics::TriangleIndex::Build(truth_b);
  ASSERT_TRUE(index.ok());
  auto mean_and_p95 = [&](const std::vector<Vector3f>& pts, float* mean, float* p95) {
    std::vector<float> d = index->DistanceBatch(pts, INFINITY, 2);
    double s = 0;
    for (float x : d) s += x;
    *mean = static_cast<float>(s / d.size());
    std::sort(d.begin(), d.end());
    *p95 = d[d.size() * 95 / 100];
  };
  float before_mean, before_p95;
  mean_and_p95(model.points, &before_mean, &before_p95);
  DeformationGraph graph;
  ASSERT_TRUE(graph.Build(model.points, DeformationGraphOptions{}).ok());
  NonrigidTracker tracker(TrackerOptions{});
  TrackResult res;
  ASSERT_TRUE(tracker.Track(rig_, target, model.points, model.normals, &graph, &res).ok());
  std::vector<Vector3f> warped;
  for (const Vector3f& p : model.points) warped.push_back(graph.Warp(p, graph.Skin(p)));
  float after_mean, after_p95;
  mean_and_p95(warped, &after_mean, &after_p95);
  std::printf("figure bend: frames %d -> %d, largest figure motion %.1f mm; distance to the true surface: "
              "before mean %.2f / p95 %.2f mm, after mean %.2f / p95 %.2f mm; data rms %.2f mm; %zu nodes, "
              "%d failed; track %.1f ms\n",
              best_t, best_t + 1, best_motion * 1000, before_mean * 1000, before_p95 * 1000, after_mean * 1000,
              after_p95 * 1000, res.data_rms_m * 1000, graph.num_nodes(), res.failed_nodes, res.total_ms);
  EXPECT_GT(best_motion, 0.03f);  // a real bend, not a still frame
  EXPECT_LT(after_mean, 0.003f);
  EXPECT_LT(after_p95, 0.008f);
  EXPECT_LT(after_mean, 0.5f * before_mean);
}

TEST(TrackerOptionsTest, BadOptionsRejected) {
  TrackerOptions o;
  EXPECT_TRUE(o.Check().ok());
  o.data_weight = -1;
  EXPECT_FALSE(o.Check().ok());
  o = TrackerOptions{};
  o.pcg_max_iterations = 0;
  EXPECT_FALSE(o.Check().ok());
  EXPECT_FALSE(ParseTrackerSolver("cholesky").ok());
  EXPECT_EQ(*ParseTrackerSolver("ceres"), TrackerSolver::kCeres);
}

// The sparse colour-feature term is on by resolution unless set: on for the
// VGA rig, off for the QVGA one.
TEST(TrackerOptionsTest, SparseTermByResolution) {
  auto qvga = GetWorkload("S8-QVGA");
  auto vga = GetWorkload("S8-VGA");
  ASSERT_TRUE(qvga.ok() && vga.ok());
  TrackerOptions o;
  EXPECT_EQ(o.use_sparse, -1);
  EXPECT_FALSE(o.SparseOn(qvga->rig));
  EXPECT_TRUE(o.SparseOn(vga->rig));
  o.use_sparse = 1;
  EXPECT_TRUE(o.SparseOn(qvga->rig));
  o.use_sparse = 0;
  EXPECT_FALSE(o.SparseOn(vga->rig));
  o.use_sparse = 2;
  EXPECT_FALSE(o.Check().ok());
}

TEST(TrackerTest2, MismatchedInputsAreErrors) {
  auto w = GetWorkload("S8-QVGA");
  ASSERT_TRUE(w.ok());
  RgbdFrameSet set;
  set.frames.resize(3);
  std::vector<Vector3f> pts(10, Vector3f::Zero()), nrm(10, Vector3f::UnitZ());
  DeformationGraph graph;
  ASSERT_TRUE(graph.Build(pts, DeformationGraphOptions{}).ok());
  NonrigidTracker tracker(TrackerOptions{});
  TrackResult res;
  EXPECT_FALSE(tracker.Track(w->rig, set, pts, nrm, &graph, &res).ok());  // 3 pods vs 8
  set.frames.resize(8);
  nrm.pop_back();
  EXPECT_FALSE(tracker.Track(w->rig, set, pts, nrm, &graph, &res).ok());  // sizes differ
  nrm.push_back(Vector3f::UnitZ());
  // Pods without data: nothing to track, no crash.
  EXPECT_TRUE(tracker.Track(w->rig, set, pts, nrm, &graph, &res).ok());
}

}  // namespace
}  // namespace holo
