// The capture site's stream mesh: the fused volume sampled on a coarser grid,
// meshed, and simplified to a triangle budget (server/fusion/stream_mesh.h).
#include "server/fusion/stream_mesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "analytic_scenes.h"
#include "common/metrics/mesh_distance.h"
#include "protocol/geometry_codec.h"
#include "protocol/surface_codec.h"
#include "server/capture/prerendered.h"
#include "server/fusion/depth_filter.h"
#include "server/fusion/edge_collapse.h"
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
  // one truncation distance (the default band's noise term is for noisy
  // depth; exact grazing rays reaching deeper move a few vertices by up to a
  // voxel).
  o.behind_band = 1.0f;
  o.depth_noise_at_1m_mm = 0;
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

// SmoothInto: every observed voxel becomes the weighted [1 2 1]³ mean of its
// observed neighbours; a linear field (a plane's TSDF, away from the
// truncation) is kept; weights and unobserved voxels are copied.
TEST(TsdfSmooth, WeightedBinomialMeanOfObservedNeighbours) {
  const Rig rig = RingRig(6, {0, 0, 1}, 1.5f);
  TsdfVolume volume(Options(0.01f));
  ASSERT_TRUE(volume.Integrate(rig, RenderAnalytic(rig, Sphere({0.013f, -0.02f, 1.0f}, 0.3f))).ok());
  TsdfVolume smooth(Options(0.01f));
  ASSERT_TRUE(volume.SmoothInto(&smooth).ok());
  EXPECT_EQ(smooth.num_blocks(), volume.num_blocks());
  size_t checked = 0, changed = 0;
  for (int64_t z = 60; z < 80; ++z)
    for (int64_t y = -20; y < 20; ++y)
      for (int64_t x = -20; x < 20; ++x) {
        float t, w, ts, wsm;
        volume.VoxelAt(x, y, z, &t, &w);
        smooth.VoxelAt(x, y, z, &ts, &wsm);
        ASSERT_EQ(wsm, w);
        if (!(w > 0)) continue;
        double num = 0, den = 0;
        for (int dz = -1; dz <= 1; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              float tn, wn;
              volume.VoxelAt(x + dx, y + dy, z + dz, &tn, &wn);
              if (!(wn > 0)) continue;
              const double k = (dx ? 1 : 2) * (dy ? 1 : 2) * (dz ? 1 : 2);
              num += k * wn * tn;
              den += k * wn;
            }
        ASSERT_NEAR(ts, num / den, 1e-5) << x << " " << y << " " << z;
        ++checked;
        changed += std::abs(ts - t) > 1e-3f;
      }
  EXPECT_GT(checked, 5000u);
  EXPECT_GT(changed, 100u);
  // Voxel size or truncation differing from the source's is refused.
  TsdfVolume other(Options(0.02f));
  EXPECT_FALSE(volume.SmoothInto(&other).ok());
  EXPECT_FALSE(volume.SmoothInto(&volume).ok());
}

// A plane's TSDF is linear across the band: smoothing does not move it.
TEST(TsdfSmooth, KeepsAPlane) {
  const Rig rig = RingRig(1, {0, 0, 1}, 1.5f);  // at (1.5, 0, 0.5), looking at (0, 0, 1)
  TsdfVolume volume(Options(0.01f));
  ASSERT_TRUE(volume.Integrate(rig, RenderAnalytic(rig, Box({-1.2f, -2, -1}, {-0.2f, 2, 3}))).ok());
  TsdfVolume smooth(Options(0.01f));
  ASSERT_TRUE(volume.SmoothInto(&smooth).ok());
  // The largest distance of a vertex to the plane, over the middle of the face.
  auto worst = [](const TsdfVolume& v, size_t* inside) {
    Mesh m;
    v.ExtractMesh(&m);
    float most = 0;
    *inside = 0;
    for (const auto& p : m.positions)
      if (std::abs(p.y()) < 0.4f && std::abs(p.z() - 1) < 0.4f) {
        most = std::max(most, std::abs(p.x() + 0.2f));
        ++*inside;
      }
    return most;
  };
  size_t n_raw = 0, n_smooth = 0;
  const float raw = worst(volume, &n_raw), smoothed = worst(smooth, &n_smooth);
  // The face's vertices stay on it: closer than before smoothing (the
  // millimetre-rounded depth ripples the unsmoothed field).
  EXPECT_GT(n_smooth, n_raw / 2);
  EXPECT_GT(n_smooth, 1000u);
  EXPECT_LE(smoothed, raw) << "raw " << raw;
  EXPECT_LT(smoothed, 1.2e-3f) << "raw " << raw;

  // A slab 20 cm thick seen by the same pod: smoothing rounds its edges but
  // grows nothing off its faces (no sheet where free space meets the inside).
  TsdfVolume slab(Options(0.01f)), slab_smooth(Options(0.01f));
  ASSERT_TRUE(slab.Integrate(rig, RenderAnalytic(rig, Box({-1, -1, 0.9f}, {1, 1, 1.1f}))).ok());
  ASSERT_TRUE(slab.SmoothInto(&slab_smooth).ok());
  Mesh m;
  slab_smooth.ExtractMesh(&m);
  ASSERT_GT(m.num_triangles(), 1000u);
  for (const auto& p : m.positions)
    ASSERT_TRUE(std::abs(p.z() - 1.1f) < 0.02f || std::abs(p.z() - 0.9f) < 0.02f || std::abs(p.x() - 1) < 0.02f)
        << p.transpose();
}

// A ring of 8 pods around (0, 0, 1) and two more above and below, so that
// the whole of a sphere there is seen (a closed full mesh).
Rig SphereRig() {
  Rig rig = RingRig(8, {0, 0, 1}, 1.5f, 240, 180);
  for (float dz : {1.4f, -1.4f}) {
    PodCalibration pod = rig.pods[0];
    pod.id = static_cast<int>(rig.pods.size());
    pod.name = "cam" + std::to_string(pod.id);
    pod.world_from_depth = LookAt(Eigen::Vector3f(0.3f, 0.2f, 1.0f + dz), Eigen::Vector3f(0, 0, 1));
    rig.pods.push_back(pod);
  }
  return rig;
}

TEST(StreamMesh, SphereStaysClosedWithinTheBudgetAndNearTheFullMesh) {
  const Rig rig = SphereRig();
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
  EXPECT_GT(st.collapses, 0u) << "short edges go first";

  // The quadric simplifier alone (no short-edge collapse) holds the same.
  {
    StreamMeshOptions qo = so;
    qo.collapse_max_edge_voxels = 0;
    auto quadric = StreamMesher::Create(o, qo);
    ASSERT_TRUE(quadric.ok());
    Mesh q;
    StreamMeshStats qs;
    ASSERT_TRUE((*quadric)->Make(volume, &q, &qs).ok());
    ExpectNoDegenerateTriangles(q);
    EXPECT_TRUE(qs.quadric);
    EXPECT_EQ(qs.collapses, 0u);
    EXPECT_LE(q.num_triangles(), so.max_triangles);
    EXPECT_TRUE(IsClosed(q));
    EXPECT_LT(MeanDistanceMm(q, full), 1.5);
  }

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


// Every directed edge once: a closed surface whose triangles all face the
// same way (outward if one does).
bool ConsistentlyOriented(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  for (const auto& [e, n] : directed)
    if (n != 1 || directed.count({e.second, e.first}) != 1) return false;
  return true;
}

// Short-edge collapse on the closed full marching-cubes mesh of a sphere:
// closed, consistently oriented, no degenerate triangle, the budget met by
// collapsing only edges below the limit, every vertex on the sphere and
// within half the limit of where a vertex was.
TEST(EdgeCollapse, ClosedMeshStaysClosedOrientedAndNear) {
  const Rig rig = SphereRig();
  const float r = 0.3f;
  TsdfVolume volume(Options(0.008f));
  ASSERT_TRUE(volume.Integrate(rig, RenderAnalytic(rig, Sphere({0, 0, 1}, r))).ok());
  Mesh full;
  volume.ExtractMesh(&full);
  ASSERT_TRUE(IsClosed(full));
  ASSERT_TRUE(ConsistentlyOriented(full));
  Mesh m = full;
  EdgeCollapseOptions eo;
  eo.target_triangles = full.num_triangles() * 85 / 100;
  eo.max_edge_m = 0.35f * 0.008f;
  EdgeCollapseStats st;
  CollapseShortEdges(eo, &m, &st);
  ExpectNoDegenerateTriangles(m);
  EXPECT_GT(st.collapses, 0u);
  EXPECT_LE(m.num_triangles(), eo.target_triangles);
  EXPECT_EQ(m.num_triangles(), full.num_triangles() - 2 * st.collapses);
  EXPECT_LE(st.longest_collapsed_m, eo.max_edge_m);
  EXPECT_TRUE(IsClosed(m));
  EXPECT_TRUE(ConsistentlyOriented(m));
  EXPECT_EQ(m.normals.size(), m.positions.size());
  // Midpoints of chords shorter than the limit stay as near the sphere as
  // the fused surface was (within 0.2 mm).
  float full_dev = 0;
  for (const auto& p : full.positions) full_dev = std::max(full_dev, std::abs((p - Eigen::Vector3f(0, 0, 1)).norm() - r));
  for (const auto& p : m.positions) {
    EXPECT_NEAR((p - Eigen::Vector3f(0, 0, 1)).norm(), r, full_dev + 0.0002f);
    float nearest = 1e9f;
    for (const auto& q : full.positions) nearest = std::min(nearest, (p - q).norm());
    EXPECT_LE(nearest, 0.5f * eo.max_edge_m + 1e-6f);
  }
  EXPECT_LT(MeanDistanceMm(m, full), 0.5);
  EXPECT_LT(MeanDistanceMm(full, m), 0.5);
}

// A tetrahedron has no edge that can go (each collapse would leave two
// copies of a triangle); a plane's border stays where it is.
TEST(EdgeCollapse, KeepsTetrahedraAndBorders) {
  Mesh tet;
  tet.positions = {{0, 0, 0}, {0.001f, 0, 0}, {0, 0.001f, 0}, {0, 0, 0.001f}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  EdgeCollapseOptions eo;
  eo.target_triangles = 0;
  eo.max_edge_m = 0.01f;
  Mesh t = tet;
  EdgeCollapseStats st;
  CollapseShortEdges(eo, &t, &st);
  EXPECT_EQ(st.collapses, 0u);
  EXPECT_EQ(t.triangles, tet.triangles);

  // A 20×20 grid of 1 cm squares whose interior vertices wander by up to
  // 3 mm: many short interior edges, and the border.
  Mesh grid;
  const int n = 20;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> jitter(-0.003f, 0.003f);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const bool border = i == 0 || j == 0 || i == n || j == n;
      grid.positions.push_back({0.01f * i + (border ? 0 : jitter(rng)), 0.01f * j + (border ? 0 : jitter(rng)), 0});
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      grid.triangles.push_back({a, b, d});
      grid.triangles.push_back({a, d, c});
    }
  auto facing_up = [](const Mesh& m) {
    size_t up = 0;
    for (const auto& t : m.triangles)
      up += (m.positions[t[1]] - m.positions[t[0]]).cross(m.positions[t[2]] - m.positions[t[0]]).z() > 0.0f;
    return up;
  };
  ASSERT_EQ(facing_up(grid), grid.num_triangles());
  const size_t border_edges = IrregularEdges(grid);
  Mesh g = grid;
  eo.max_edge_m = 0.0065f;
  CollapseShortEdges(eo, &g, &st);
  ExpectNoDegenerateTriangles(g);
  EXPECT_GT(st.collapses, 5u);
  EXPECT_EQ(IrregularEdges(g), border_edges) << "the border keeps its edges and nothing else opens";
  size_t border_kept = 0;
  for (const auto& p : g.positions) {
    const float x = p.x() / 0.01f, y = p.y() / 0.01f;
    const bool on_border = std::abs(x) < 1e-4f || std::abs(y) < 1e-4f || std::abs(x - n) < 1e-4f ||
                           std::abs(y - n) < 1e-4f;
    border_kept += on_border && std::abs(x - std::round(x)) < 1e-4f && std::abs(y - std::round(y)) < 1e-4f;
  }
  EXPECT_EQ(border_kept, static_cast<size_t>(4 * n)) << "every border vertex in place";
  EXPECT_EQ(facing_up(g), g.num_triangles()) << "no triangle flipped";
}

TEST(StreamMesh, RefusesBadOptions) {
  StreamMeshOptions so;
  so.step = 0;
  EXPECT_FALSE(StreamMesher::Create(Options(0.008f), so).ok());
  so.step = 2;
  so.max_triangles = 10;
  EXPECT_FALSE(StreamMesher::Create(Options(0.008f), so).ok());
  so.max_triangles = 20000;
  so.collapse_max_edge_voxels = 1.5f;
  EXPECT_FALSE(StreamMesher::Create(Options(0.008f), so).ok());
  so.collapse_max_edge_voxels = 0.35f;
  so.step = 4;
  TsdfOptions thin = Options(0.008f);
  thin.truncation_voxels = 3;  // 3/4 of a coarse voxel: cannot be represented
  EXPECT_FALSE(StreamMesher::Create(thin, so).ok());
}

// A studio frame set with the studio's exact masks.
RgbdFrameSet FramesWithTruthMasks(SyntheticStudio* studio, int64_t frame) {
  RgbdFrameSet frames;
  StudioGroundTruth gt;
  studio->RenderFrame(frame, &frames, &gt);
  for (size_t p = 0; p < frames.frames.size(); ++p) frames.frames[p].mask = gt.mask[p];
  return frames;
}

// The studio's person fused from its 8 QVGA pods (exact masks): the stream
// mesh keeps the budget and stays within 1.5 mm (mean) of the full mesh.
TEST(StreamMesh, FusedStudioFrameMeetsBudgetAndErrorBound) {
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  RgbdFrameSet frames = FramesWithTruthMasks(studio->get(), 12);
  // As the capture site does: depth filtered within the masks, and the full
  // mesh extracted from the volume smoothed on its own grid.
  auto filter = DepthFilter::Create(DepthFilterOptions{});
  ASSERT_TRUE(filter.ok());
  ASSERT_TRUE((*filter)->Apply(&frames).ok());
  TsdfOptions o;
  o.voxel_size = workload->voxel_size_m;
  TsdfVolume volume(o), smoothed(o);
  ASSERT_TRUE(volume.Integrate(workload->rig, frames).ok());
  ASSERT_TRUE(volume.SmoothInto(&smoothed).ok());
  Mesh full, raw;
  smoothed.ExtractMesh(&full);
  volume.ExtractMesh(&raw);
  auto mesher = StreamMesher::Create(o, StreamMeshOptions{});
  ASSERT_TRUE(mesher.ok());
  Mesh stream;
  StreamMeshStats st;
  ASSERT_TRUE((*mesher)->Make(volume, &stream, &st).ok());
  ExpectNoDegenerateTriangles(stream);
  EXPECT_LE(stream.num_triangles(), StreamMeshOptions{}.max_triangles);
  EXPECT_GT(stream.num_triangles(), 5000u);
  // Within 1.5 mm of the full mesh, both ways (1.2 and 1.0 mm measured).
  // Against the unsmoothed volume's mesh it would be 1.8 mm: what is left
  // of the depth noise folds that mesh at the scale of a voxel.
  EXPECT_LT(MeanDistanceMm(stream, full), 1.5);
  EXPECT_LT(MeanDistanceMm(full, stream), 1.5);
  EXPECT_LT(full.num_triangles(), raw.num_triangles());
  // Against the truth the stream mesh loses nothing, and smoothing makes the
  // full mesh more accurate (3.8 → 3.1 mm, mean distance to the truth).
  const Mesh truth = (*studio)->ForegroundMesh(12);
  auto full_truth = metrics::ComputeMeshDistance(full, truth);
  auto raw_truth = metrics::ComputeMeshDistance(raw, truth);
  auto stream_truth = metrics::ComputeMeshDistance(stream, truth);
  ASSERT_TRUE(full_truth.ok() && stream_truth.ok() && raw_truth.ok());
  EXPECT_LT(stream_truth->chamfer_mm, full_truth->chamfer_mm + 0.3);
  EXPECT_LT(full_truth->accuracy_mm, raw_truth->accuracy_mm);
  // Reused buffers give the same mesh on the next call.
  Mesh again;
  ASSERT_TRUE((*mesher)->Make(volume, &again).ok());
  EXPECT_EQ(again.triangles, stream.triangles);
}

// G3 (protocol/surface_codec.h) codes the grid the stream mesh comes from:
// with a fine value step and no fragment removal the viewer's marching cubes
// gives the site's own coarse mesh back; with the defaults it stays within
// a millimetre of the published stream mesh at well under G1's bytes.
TEST(StreamMesh, G3GridGivesTheSitesMeshBack) {
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  const RgbdFrameSet frames = FramesWithTruthMasks(studio->get(), 30);
  TsdfOptions o;
  o.voxel_size = workload->voxel_size_m;
  TsdfVolume volume(o);
  ASSERT_TRUE(volume.Integrate(workload->rig, frames).ok());
  StreamMeshOptions raw_options;
  raw_options.max_triangles = 0;
  raw_options.min_component_triangles = 0;
  auto raw_mesher = StreamMesher::Create(o, raw_options);
  ASSERT_TRUE(raw_mesher.ok());
  Mesh coarse;
  SdfGrid grid;
  ASSERT_TRUE((*raw_mesher)->Make(volume, &coarse, nullptr, &grid).ok());
  ASSERT_GT(coarse.num_triangles(), 5000u);
  EXPECT_NEAR(grid.voxel_m, 2 * workload->voxel_size_m, 1e-7);

  protocol::SurfaceEncodeOptions exact;
  exact.position_step_m = grid.voxel_m / 255;
  exact.min_component_triangles = 0;
  std::vector<uint8_t> blob;
  ASSERT_TRUE(protocol::EncodeSurface(grid, exact, &blob).ok());
  Mesh decoded;
  ASSERT_TRUE(protocol::DecodeGeometry(blob, &decoded).ok());
  EXPECT_EQ(decoded.num_triangles(), coarse.num_triangles());
  EXPECT_EQ(decoded.num_vertices(), coarse.num_vertices());
  // (Edges the labels take for grazing get fewer levels: 0.1 mm.)
  EXPECT_LT(MeanDistanceMm(decoded, coarse), 0.2);
  EXPECT_LT(MeanDistanceMm(coarse, decoded), 0.2);

  // Defaults: 2 mm steps, small fragments dropped, against what the site
  // publishes (simplified to its 10 000 triangles) and its G1 bytes.
  auto mesher = StreamMesher::Create(o, StreamMeshOptions{});
  ASSERT_TRUE(mesher.ok());
  Mesh stream;
  ASSERT_TRUE((*mesher)->Make(volume, &stream, nullptr, &grid).ok());
  blob.clear();
  protocol::SurfaceEncodeStats st;
  ASSERT_TRUE(protocol::EncodeSurface(grid, {}, &blob, nullptr, &st).ok());
  ASSERT_TRUE(protocol::DecodeGeometry(blob, &decoded).ok());
  EXPECT_LT(MeanDistanceMm(decoded, stream), 1.0);
  EXPECT_LT(MeanDistanceMm(stream, decoded), 1.0);
  protocol::GeometryEncodeOptions g1;
  g1.position_step_m = 0.002f;
  g1.colors = false;  // as the site sends it (the viewer colours from the pods' images)
  std::vector<uint8_t> g1_blob;
  ASSERT_TRUE(protocol::EncodeGeometry(stream, g1, &g1_blob).ok());
  // G3 carries the whole unsimplified surface (26 k triangles here) in fewer
  // bytes than G1 needs for the 10 k it is simplified to (7.6 against 12.2 KB
  // measured).
  EXPECT_LT(blob.size(), g1_blob.size() * 3 / 4) << "G3 " << blob.size() << " B, G1 " << g1_blob.size() << " B";
  std::printf("G3 %zu B (bricks %zu, labels %zu, crossings %zu; %zu triangles), G1 2 mm %zu B (%zu triangles)\n",
              blob.size(), st.brick_bytes, st.label_bytes, st.crossing_bytes, decoded.num_triangles(), g1_blob.size(),
              stream.num_triangles());
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
