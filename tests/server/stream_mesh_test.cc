// The capture site's stream mesh: the fused volume sampled on a coarser grid,
// meshed, and simplified to a triangle budget (server/fusion/stream_mesh.h).
#include "server/fusion/stream_mesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "analytic_scenes.h"
#include "common/metrics/mesh_distance.h"
#include "server/capture/prerendered.h"
#include "server/fusion/tsdf.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

// Edges (undirected) not used by exactly two triangles: boundary or non-manifold.
size_t IrregularEdges(const Mesh& m, size_t* total = nullptr) {
  std::map<std::pair<uint32_t, uint32_t>, int> edges;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = t[k], b = t[(k + 1) % 3];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  size_t bad = 0;
  for (const auto& [e, n] : edges) bad += n != 2;
  if (total) *total = edges.size();
  return bad;
}

// Every undirected edge used by exactly two triangles: a closed surface.
bool IsClosed(const Mesh& m) {
  size_t total = 0;
  return IrregularEdges(m, &total) == 0 && total > 0;
}

void ExpectNoDegenerateTriangles(const Mesh& m) {
  ASSERT_TRUE(m.Validate().ok()) << m.Validate().ToString();
  for (const auto& t : m.triangles) {
    ASSERT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
    const Eigen::Vector3f n = (m.positions[t[1]] - m.positions[t[0]]).cross(m.positions[t[2]] - m.positions[t[0]]);
    ASSERT_GT(n.norm(), 1e-12f);
  }
}

// Mean distance (mm) from the vertices of `a` to the surface of `b`.
double MeanDistanceMm(const Mesh& a, const Mesh& b) {
  auto d = metrics::ComputeMeshDistance(a, b);
  EXPECT_TRUE(d.ok()) << d.status().ToString();
  return d.ok() ? d->accuracy_mm : 1e9;
}

TsdfOptions Options(float voxel) {
  TsdfOptions o;
  o.voxel_size = voxel;
  o.truncation_voxels = 4;
  // The scenes here have exact depth: observations behind the surface end at
  // one truncation distance (the default band is for noisy depth; exact
  // grazing rays reaching deeper move a few vertices by up to a voxel).
  o.behind_band = 1.0f;
  o.threads = 2;
  return o;
}

// Checks every coarse voxel in x, y ∈ [−r, r), z ∈ [z0, z1) against the
// weighted mean of its step³ fine voxels; returns how many were observed.
size_t CheckDownsample(const TsdfVolume& fine, const TsdfVolume& coarse, int step, int64_t r, int64_t z0, int64_t z1) {
  size_t checked = 0;
  for (int64_t z = z0; z < z1; ++z)
    for (int64_t y = -r; y < r; ++y)
      for (int64_t x = -r; x < r; ++x) {
        double tw = 0, w = 0;
        int n = 0;
        for (int dz = 0; dz < step; ++dz)
          for (int dy = 0; dy < step; ++dy)
            for (int dx = 0; dx < step; ++dx) {
              float tf, wf;
              fine.VoxelAt(step * x + dx, step * y + dy, step * z + dz, &tf, &wf);
              if (wf > 0) {
                tw += static_cast<double>(tf) * wf;
                w += wf;
                ++n;
              }
            }
        float tc, wc;
        coarse.VoxelAt(x, y, z, &tc, &wc);
        if (n == 0) {
          EXPECT_EQ(wc, 0.0f) << x << " " << y << " " << z;
          if (wc != 0.0f) return checked;
          continue;
        }
        EXPECT_NEAR(wc, w / n, 1e-4 * w) << x << " " << y << " " << z;
        EXPECT_NEAR(tc, tw / w, 1e-5) << x << " " << y << " " << z;
        if (std::abs(tc - tw / w) > 1e-5) return checked;
        ++checked;
      }
  return checked;
}

TEST(TsdfDownsample, CopiesEveryStepthVoxelAndRefusesMismatchedVolumes) {
  const Rig rig = RingRig(6, {0, 0, 1}, 1.5f);
  TsdfVolume fine(Options(0.01f));
  ASSERT_TRUE(fine.Integrate(rig, RenderAnalytic(rig, Sphere({0.013f, -0.02f, 1.0f}, 0.3f))).ok());
  TsdfVolume coarse(Options(0.02f));
  // Truncation in metres must match: 4 fine voxels = 2 coarse ones.
  EXPECT_FALSE(fine.DownsampleInto(2, &coarse).ok());
  TsdfOptions co = Options(0.02f);
  co.truncation_voxels = 2;
  TsdfVolume coarse2(co);
  EXPECT_FALSE(fine.DownsampleInto(3, &coarse2).ok()) << "voxel size 2 cm is not 3 × 1 cm";
  ASSERT_TRUE(fine.DownsampleInto(2, &coarse2).ok());
  EXPECT_GT(CheckDownsample(fine, coarse2, 2, 20, 40, 60), 1000u);
  // An odd step: coarse cells straddle fine blocks, and negative coordinates round down.
  TsdfOptions co3 = Options(0.03f);
  co3.truncation_voxels = 4.0f / 3.0f;
  TsdfVolume coarse3(co3);
  ASSERT_TRUE(fine.DownsampleInto(3, &coarse3).ok());
  EXPECT_GT(CheckDownsample(fine, coarse3, 3, 14, 27, 40), 500u);
  EXPECT_FLOAT_EQ(fine.DownsampleOffset(2), 0.005f);
}

TEST(StreamMesh, SphereStaysClosedWithinTheBudgetAndNearTheFullMesh) {
  Rig rig = RingRig(8, {0, 0, 1}, 1.5f, 240, 180);
  // Two more pods above and below so that the whole sphere is seen (a closed full mesh).
  for (float dz : {1.4f, -1.4f}) {
    PodCalibration pod = rig.pods[0];
    pod.id = static_cast<int>(rig.pods.size());
    pod.name = "cam" + std::to_string(pod.id);
    pod.world_from_depth = LookAt(Eigen::Vector3f(0.3f, 0.2f, 1.0f + dz), Eigen::Vector3f(0, 0, 1));
    rig.pods.push_back(pod);
  }
  const float r = 0.35f;
  const TsdfOptions o = Options(0.008f);
  TsdfVolume volume(o);
  ASSERT_TRUE(volume.Integrate(rig, RenderAnalytic(rig, Sphere({0, 0, 1}, r))).ok());
  Mesh full;
  volume.ExtractMesh(&full);
  ASSERT_TRUE(IsClosed(full));

  StreamMeshOptions so;
  so.step = 2;
  so.max_triangles = 4000;
  auto mesher = StreamMesher::Create(o, so);
  ASSERT_TRUE(mesher.ok()) << mesher.status().ToString();
  Mesh stream;
  StreamMeshStats st;
  ASSERT_TRUE((*mesher)->Make(volume, &stream, &st).ok());
  ExpectNoDegenerateTriangles(stream);
  EXPECT_LE(stream.num_triangles(), so.max_triangles);
  EXPECT_GT(st.coarse_triangles, so.max_triangles) << "the budget must have made the simplifier work";
  EXPECT_LT(st.coarse_triangles, full.num_triangles() / 3) << "step 2 should give about a quarter of the triangles";
  EXPECT_TRUE(IsClosed(stream)) << "a closed input must stay closed";
  EXPECT_EQ(stream.normals.size(), stream.positions.size());
  // Geometric error against the full mesh, both ways.
  EXPECT_LT(MeanDistanceMm(stream, full), 1.5);
  EXPECT_LT(MeanDistanceMm(full, stream), 1.5);
  for (const auto& p : stream.positions) EXPECT_NEAR((p - Eigen::Vector3f(0, 0, 1)).norm(), r, 0.006f);

  // Without a budget the coarse mesh is published as extracted.
  so.max_triangles = 0;
  auto plain = StreamMesher::Create(o, so);
  ASSERT_TRUE(plain.ok());
  Mesh coarse;
  ASSERT_TRUE((*plain)->Make(volume, &coarse, &st).ok());
  EXPECT_EQ(coarse.num_triangles(), st.coarse_triangles);
  // Where a coarse cube has a corner no view observed (the truncation band is
  // 2 coarse voxels deep) marching cubes leaves it out: a few tiny holes,
  // stated here as at most 0.1 % of the edges.
  size_t edges = 0;
  const size_t irregular = IrregularEdges(coarse, &edges);
  EXPECT_LE(irregular * 1000, edges) << irregular << " of " << edges << " edges are boundary or non-manifold";
}

TEST(StreamMesh, RefusesBadOptions) {
  StreamMeshOptions so;
  so.step = 0;
  EXPECT_FALSE(StreamMesher::Create(Options(0.008f), so).ok());
  so.step = 2;
  so.max_triangles = 10;
  EXPECT_FALSE(StreamMesher::Create(Options(0.008f), so).ok());
  so.max_triangles = 20000;
  so.step = 4;
  TsdfOptions thin = Options(0.008f);
  thin.truncation_voxels = 3;  // 3/4 of a coarse voxel: cannot be represented
  EXPECT_FALSE(StreamMesher::Create(thin, so).ok());
}

// The studio's person fused from its 8 QVGA pods (exact masks): the stream
// mesh keeps the budget and stays within 1.5 mm (mean) of the full mesh.
TEST(StreamMesh, FusedStudioFrameMeetsBudgetAndErrorBound) {
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  RgbdFrameSet frames;
  StudioGroundTruth gt;
  (*studio)->RenderFrame(12, &frames, &gt);
  for (size_t p = 0; p < frames.frames.size(); ++p) frames.frames[p].mask = gt.mask[p];
  TsdfOptions o;
  o.voxel_size = workload->voxel_size_m;
  TsdfVolume volume(o);
  ASSERT_TRUE(volume.Integrate(workload->rig, frames).ok());
  Mesh full;
  volume.ExtractMesh(&full);
  auto mesher = StreamMesher::Create(o, StreamMeshOptions{});
  ASSERT_TRUE(mesher.ok());
  Mesh stream;
  StreamMeshStats st;
  ASSERT_TRUE((*mesher)->Make(volume, &stream, &st).ok());
  ExpectNoDegenerateTriangles(stream);
  EXPECT_LE(stream.num_triangles(), 20000u);
  EXPECT_GT(stream.num_triangles(), 5000u);
  // Against the full fused mesh the stream mesh is 2.2–2.3 mm away on
  // average: the full mesh's depth-noise folds (it has 7× the triangles)
  // are what the box filter smooths. Against the truth it loses little.
  EXPECT_LT(MeanDistanceMm(stream, full), 2.6);
  const Mesh truth = (*studio)->ForegroundMesh(12);
  auto full_truth = metrics::ComputeMeshDistance(full, truth);
  auto stream_truth = metrics::ComputeMeshDistance(stream, truth);
  ASSERT_TRUE(full_truth.ok() && stream_truth.ok());
  EXPECT_LT(stream_truth->chamfer_mm, full_truth->chamfer_mm + 1.0);
  // Reused buffers give the same mesh on the next call.
  Mesh again;
  ASSERT_TRUE((*mesher)->Make(volume, &again).ok());
  EXPECT_EQ(again.triangles, stream.triangles);
}

TEST(PrerenderedSource, LoopsForwardAndBackWithRunningFrameIndices) {
  EXPECT_EQ(LoopContent(0, 4), 0);
  std::vector<int64_t> seq;
  for (int k = 0; k < 9; ++k) seq.push_back(LoopContent(k, 4));
  EXPECT_EQ(seq, (std::vector<int64_t>{0, 1, 2, 3, 2, 1, 0, 1, 2}));
  EXPECT_EQ(LoopContent(5, 1), 0);

  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  auto looped = PrerenderedSource::Render(**studio, 3, /*loop=*/true);
  ASSERT_TRUE(looped.ok());
  EXPECT_EQ((*looped)->num_frames(), -1);
  RgbdFrameSet f;
  for (int64_t k = 0; k < 6; ++k) {
    ASSERT_TRUE((*looped)->Next(&f).ok());
    EXPECT_EQ(f.frame_index, k);
    const int64_t content = (*looped)->ContentFrame(k);
    EXPECT_EQ(content, LoopContent(k, 3));
    const auto& stored = (*looped)->frames()[static_cast<size_t>(content)];
    EXPECT_TRUE(std::equal(f.frames[3].depth.data(), f.frames[3].depth.data() + f.frames[3].depth.num_pixels(),
                           stored.frames[3].depth.data()));
  }
  auto once = PrerenderedSource::Render(**studio, 2, /*loop=*/false);
  ASSERT_TRUE(once.ok());
  ASSERT_TRUE((*once)->Next(&f).ok());
  ASSERT_TRUE((*once)->Next(&f).ok());
  EXPECT_EQ((*once)->Next(&f).code(), StatusCode::kOutOfRange);
  EXPECT_FALSE(PrerenderedSource::Render(**studio, 0, true).ok());
}

}  // namespace
}  // namespace holo
