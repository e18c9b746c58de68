#include "texture/texturer.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "common/metrics/mesh_shapes.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/mesh_renderer.h"
#include "texture/novel_view.h"

namespace holo {
// Counts heap allocations in this test binary (steady-state check below).
std::atomic<size_t> g_allocations{0};
}  // namespace holo

void* operator new(std::size_t size) {
  holo::g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
// GCC (-O2 with sanitizers) sees the replaced operator new and delete inlined
// into gtest's code and reports malloc/free as mismatched with new/delete.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

namespace holo {
namespace {

using Eigen::Vector3f;
using Rgb = std::array<uint8_t, 3>;

void Paint(Mesh* mesh, Rgb c) { mesh->colors.assign(mesh->num_vertices(), c); }

PodCalibration MakePod(int id, const Vector3f& eye, const Vector3f& target, int width = 320, int height = 240,
                       const Vector3f& up = Vector3f::UnitZ()) {
  PodCalibration pod;
  pod.id = id;
  pod.name = "pod" + std::to_string(id);
  pod.depth = pod.color = Intrinsics::FromFov(width, height, 70.0);
  pod.world_from_depth = LookAt(eye, target, up);
  return pod;
}

// Renders every pod's colour image of the coloured `scene` (the background
// colour where the scene leaves a pixel empty).
RgbdFrameSet RenderPods(const Rig& rig, const Mesh& scene, Rgb background = {0, 0, 0}) {
  RgbdFrameSet set;
  MeshRenderOptions ro;
  ro.background = background;
  for (const PodCalibration& pod : rig.pods) {
    RgbdFrame f;
    f.pod_id = pod.id;
    const Status s = RenderMesh(scene, pod.ColorCamera(), &f.color, nullptr, nullptr, ro);
    HOLO_CHECK_MSG(s.ok(), s.ToString());
    set.frames.push_back(std::move(f));
  }
  return set;
}

double ColorDistance(const Rgb& a, const Rgb& b) {
  double s = 0;
  for (int c = 0; c < 3; ++c) s += (double(a[c]) - b[c]) * (double(a[c]) - b[c]);
  return std::sqrt(s);
}

// ---------------------------------------------------------------- RenderMesh

// Camera at the origin looking along +z (camera frame = world frame).
CameraModel FrontCamera() {
  CameraModel cam;
  cam.intrinsics.width = 64;
  cam.intrinsics.height = 48;
  cam.intrinsics.fx = cam.intrinsics.fy = 100;
  // Off-integer principal point: no pixel centre lies exactly on an edge.
  cam.intrinsics.cx = 31.7;
  cam.intrinsics.cy = 23.7;
  return cam;
}

// Axis-aligned rectangle at depth z, x in [x0, x1], y in [y0, y1], facing the camera (−z).
Mesh Rectangle(float x0, float x1, float y0, float y1, float z, Rgb left, Rgb right) {
  Mesh m;
  m.positions = {{x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}};
  m.colors = {left, right, right, left};
  m.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

TEST(MeshRendererTest, RectangleCoversExpectedPixelsWithExactDepthAndColour) {
  // x ∈ [−0.2, 0.2] at z = 2 → u ∈ [21.7, 41.7] → columns 22..41; rows 19..28.
  const Mesh rect = Rectangle(-0.2f, 0.2f, -0.1f, 0.1f, 2.0f, {10, 20, 30}, {10, 20, 30});
  ImageRgb8 color;
  ImageDepth16 depth;
  ImageGray8 mask;
  MeshRenderOptions o;
  o.background = {1, 2, 3};
  ASSERT_TRUE(RenderMesh(rect, FrontCamera(), &color, &depth, &mask, o).ok());
  ASSERT_EQ(color.width(), 64);
  ASSERT_EQ(depth.height(), 48);
  int covered = 0;
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      const bool inside = x >= 22 && x <= 41 && y >= 19 && y <= 28;
      covered += mask.at(x, y) != 0;
      EXPECT_EQ(mask.at(x, y) != 0, inside) << x << "," << y;
      EXPECT_EQ(depth.at(x, y), inside ? 2000 : 0) << x << "," << y;
      const Rgb want = inside ? Rgb{10, 20, 30} : Rgb{1, 2, 3};
      for (int c = 0; c < 3; ++c) EXPECT_EQ(color.at(x, y, c), want[c]) << x << "," << y;
    }
  EXPECT_EQ(covered, 200);
}

TEST(MeshRendererTest, GouraudInterpolationAndNearestSurfaceWins) {
  Mesh scene = Rectangle(-0.2f, 0.2f, -0.1f, 0.1f, 2.0f, {0, 0, 0}, {200, 200, 200});
  // A nearer red square over the left part.
  scene.Append(Rectangle(-0.3f, -0.1f, -0.05f, 0.05f, 1.0f, {255, 0, 0}, {255, 0, 0}));
  ImageRgb8 color;
  ImageDepth16 depth;
  ASSERT_TRUE(RenderMesh(scene, FrontCamera(), &color, &depth, nullptr).ok());
  // Left square: x ∈ [−0.3, −0.1] at z = 1 → u ∈ [1.7, 21.7]; rows 19..28 cut to v ∈ [18.7, 28.7] at z=1 → 19..28.
  EXPECT_EQ(depth.at(10, 23), 1000);
  EXPECT_EQ(color.at(10, 23, 0), 255);
  EXPECT_EQ(color.at(10, 23, 1), 0);
  // Far rectangle right of the red square: colour linear in x (fronto-parallel, so affine = perspective).
  for (int x = 23; x <= 41; ++x) {
    const double xw = (x - 31.7) * 2.0 / 100.0;          // world x at the pixel centre
    const double expect = 200.0 * (xw + 0.2) / 0.4;      // 0 at x = −0.2, 200 at x = 0.2
    EXPECT_NEAR(color.at(x, 23, 1), expect, 1.0) << x;
    EXPECT_EQ(depth.at(x, 23), 2000) << x;
  }
}

TEST(MeshRendererTest, TiltedPlaneDepthIsPerspectiveCorrect) {
  // A plane tilted about the y axis: z = 2 + 0.5·x. The depth at each pixel
  // must be that of the plane along the pixel's ray, not an affine blend.
  Mesh m;
  m.positions = {{-0.5f, -0.3f, 1.75f}, {0.5f, -0.3f, 2.25f}, {0.5f, 0.3f, 2.25f}, {-0.5f, 0.3f, 1.75f}};
  m.triangles = {{0, 2, 1}, {0, 3, 2}};
  ImageDepth16 depth;
  const CameraModel cam = FrontCamera();
  ASSERT_TRUE(RenderMesh(m, cam, nullptr, &depth, nullptr).ok());
  for (int x = 5; x < 60; x += 6) {
    const double xn = (x - 31.7) / 100.0;  // x/z along the ray
    const double z = 2.0 / (1.0 - 0.5 * xn);  // z = 2 + 0.5·xn·z
    if (std::abs(xn * z) > 0.48) continue;
    EXPECT_NEAR(depth.at(x, 24), z * 1000.0, 1.0) << x;
  }
}

TEST(MeshRendererTest, BackFaceCullingKeepsTheVisibleSurfaceOfAClosedMesh) {
  // Culling works on the sign of the screen area (pinhole cameras): on a
  // closed mesh it must drop exactly the faces that never win the z-test.
  const Mesh sphere = metrics::MakeSphereMesh({0.05f, -0.02f, 2.0f}, 0.4f, 4);
  MeshRenderOptions o;
  ImageDepth16 all, front;
  ImageGray8 mask_all, mask_front;
  ASSERT_TRUE(RenderMesh(sphere, FrontCamera(), nullptr, &all, &mask_all, o).ok());
  o.cull_back_faces = true;
  ASSERT_TRUE(RenderMesh(sphere, FrontCamera(), nullptr, &front, &mask_front, o).ok());
  int covered = 0;
  for (int y = 0; y < all.height(); ++y)
    for (int x = 0; x < all.width(); ++x) {
      covered += mask_all.at(x, y) != 0;
      EXPECT_EQ(mask_front.at(x, y), mask_all.at(x, y)) << x << "," << y;
      EXPECT_EQ(front.at(x, y), all.at(x, y)) << x << "," << y;
    }
  EXPECT_GT(covered, 200);
  // Inside out: only the far hemisphere faces the camera, so it is drawn.
  Mesh inverted = sphere;
  for (auto& t : inverted.triangles) std::swap(t[1], t[2]);
  ASSERT_TRUE(RenderMesh(inverted, FrontCamera(), nullptr, &front, &mask_front, o).ok());
  for (int y = 0; y < front.height(); ++y)
    for (int x = 0; x < front.width(); ++x) {
      EXPECT_EQ(mask_front.at(x, y), mask_all.at(x, y)) << x << "," << y;
      if (mask_all.at(x, y) != 0) {
        EXPECT_GT(front.at(x, y), all.at(x, y)) << x << "," << y;
      }
    }
}

TEST(MeshRendererTest, BadInputsGiveErrors) {
  Mesh m = Rectangle(-0.2f, 0.2f, -0.1f, 0.1f, 2.0f, {1, 1, 1}, {1, 1, 1});
  CameraModel cam = FrontCamera();
  cam.intrinsics.fx = -1;
  ImageRgb8 color;
  EXPECT_EQ(RenderMesh(m, cam, &color, nullptr, nullptr).code(), StatusCode::kInvalidArgument);
  m.triangles.push_back({0, 1, 7});
  EXPECT_EQ(RenderMesh(m, FrontCamera(), &color, nullptr, nullptr).code(), StatusCode::kDataLoss);
  MeshRenderOptions o;
  o.near_m = 0;
  m.triangles.pop_back();
  EXPECT_EQ(RenderMesh(m, FrontCamera(), &color, nullptr, nullptr, o).code(), StatusCode::kInvalidArgument);
}

// ------------------------------------------------------------------ Texturer

// Wall: plane z = 0 (2 × 2 m, 2.5 cm cells), white. Bar: 8 cm × 8 cm red
// beam along y, 30 cm above the wall. Pods A (x = −1) and B (x = +1) look
// down at the wall from 2 m: the bar hides a strip x ≈ +0.18 from A and a
// strip x ≈ −0.18 from B; each strip is seen by the other pod alone.
struct GhostScene {
  Rig rig;
  Mesh wall, bar, scene;
  RgbdFrameSet frames;
};

GhostScene MakeGhostScene() {
  GhostScene g;
  g.rig.name = "ghost";
  g.rig.pods.push_back(MakePod(0, {-1.0f, 0.0f, 2.0f}, {0, 0, 0}, 320, 240, Vector3f::UnitY()));
  g.rig.pods.push_back(MakePod(1, {1.0f, 0.0f, 2.0f}, {0, 0, 0}, 320, 240, Vector3f::UnitY()));
  g.wall = metrics::MakePlaneMesh({0, 0, 0}, 2.0f, 2.0f, 80, 80);
  Paint(&g.wall, {240, 240, 240});
  g.bar = metrics::MakeBoxMesh({0, 0, 0.3f}, {0.08f, 1.6f, 0.08f}, 4);
  Paint(&g.bar, {220, 20, 20});
  g.scene = g.wall;
  g.scene.Append(g.bar);
  g.frames = RenderPods(g.rig, g.scene);
  return g;
}

// Wall vertices hidden from pod A or pod B by the bar (|y| < 0.5).
std::vector<size_t> HiddenWallVertices(const GhostScene& g) {
  std::vector<size_t> out;
  for (size_t v = 0; v < g.wall.num_vertices(); ++v) {
    const Vector3f& p = g.wall.positions[v];
    if (std::abs(p.y()) > 0.5f) continue;
    // Where the ray from each pod through the bar's axis meets the wall: x = ±0.3/1.7.
    const float d = std::min(std::abs(p.x() - 0.1765f), std::abs(p.x() + 0.1765f));
    if (d < 0.02f) out.push_back(v);
  }
  return out;
}

TEST(TexturerTest, GhostOccludedWallDoesNotTakeOccluderColour) {
  const GhostScene g = MakeGhostScene();
  const std::vector<size_t> hidden = HiddenWallVertices(g);
  ASSERT_GT(hidden.size(), 50u);
  for (int voting : {0, 3}) {
    TextureOptions o;
    o.voting_levels = voting;
    o.threads = 2;
    Texturer t(g.rig, o);
    Mesh mesh = g.scene;
    mesh.colors.clear();
    ASSERT_TRUE(t.Apply(g.frames, &mesh).ok());
    double worst = 0;
    for (size_t v : hidden) worst = std::max(worst, ColorDistance(mesh.colors[v], {240, 240, 240}));
    EXPECT_LT(worst, 12.0) << "voting levels " << voting;
    // The bar itself keeps its colour on the faces the pods see (top face).
    const size_t bar0 = g.wall.num_vertices();
    int red = 0, top = 0;
    for (size_t v = bar0; v < mesh.num_vertices(); ++v) {
      const Vector3f& p = mesh.positions[v];
      if (p.z() < 0.339f || std::abs(p.y()) > 0.5f || std::abs(p.x()) > 0.025f) continue;
      ++top;
      red += ColorDistance(mesh.colors[v], {220, 20, 20}) < 12.0;
    }
    EXPECT_GT(top, 0);
    EXPECT_EQ(red, top);
  }
  // The case is discriminating: without the visibility test the occluder is
  // projected onto the wall.
  TextureOptions naive;
  naive.visibility_test = naive.discontinuity_test = false;
  naive.voting_levels = 0;
  Texturer t(g.rig, naive);
  Mesh mesh = g.scene;
  ASSERT_TRUE(t.Apply(g.frames, &mesh).ok());
  double mean = 0;
  for (size_t v : hidden) mean += ColorDistance(mesh.colors[v], {240, 240, 240});
  EXPECT_GT(mean / hidden.size(), 60.0);
}

TEST(TexturerTest, AllPodRasterMatchesMeshRasterizer) {
  // The texturer draws every pod's visibility map in one pass (four pods per
  // vector); it must give exactly MeshRasterizer's depth maps, for the ghost
  // scene and for a fine studio mesh seen by the 8 pods of S8-QVGA.
  const GhostScene g = MakeGhostScene();
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  RgbdFrameSet set;
  StudioGroundTruth gt;
  (*studio)->RenderFrame(20, &set, &gt);
  struct Case {
    const Rig* rig;
    const RgbdFrameSet* frames;
    Mesh mesh;
  };
  const Case cases[] = {{&g.rig, &g.frames, g.scene}, {&workload->rig, &set, gt.foreground_mesh}};
  for (const Case& c : cases) {
    TextureOptions o;
    o.threads = 2;
    Texturer t(*c.rig, o);
    Mesh mesh = c.mesh;
    ASSERT_TRUE(t.Apply(*c.frames, &mesh).ok());
    for (size_t pod = 0; pod < c.rig->pods.size(); ++pod) {
      MeshRasterizer r;
      r.Rasterize(c.mesh.positions, c.mesh.triangles, c.rig->pods[pod].ColorCamera(), false, true, 0.05f);
      const std::vector<float>& ours = t.RasterInverseDepth(static_cast<int>(pod));
      ASSERT_EQ(ours.size(), r.inv_z().size());
      size_t drawn = 0, differ = 0;
      for (size_t i = 0; i < ours.size(); ++i) {
        drawn += r.inv_z()[i] > 0.0f;
        differ += ours[i] != r.inv_z()[i];
      }
      EXPECT_GT(drawn, 100u) << "pod " << pod;
      EXPECT_EQ(differ, 0u) << "pod " << pod;
    }
    // And the vectorized view tests give the scalar path's colours.
    TextureOptions scalar = o;
    scalar.vectorize = false;
    Texturer ts(*c.rig, scalar);
    Mesh reference = c.mesh;
    ASSERT_TRUE(ts.Apply(*c.frames, &reference).ok());
    size_t colour_differ = 0;
    for (size_t v = 0; v < mesh.num_vertices(); ++v) colour_differ += mesh.colors[v] != reference.colors[v];
    EXPECT_EQ(colour_differ, 0u);
  }
}

TEST(TexturerTest, ClusteredTexturingKeepsTheGhostTest) {
  // TextureOptions::cluster_size_m (off by default): texturing a clustered
  // copy of the mesh must not let the occluder's colour onto the wall either.
  const GhostScene g = MakeGhostScene();
  const std::vector<size_t> hidden = HiddenWallVertices(g);
  for (int transfer : {0, 1, 2}) {
    TextureOptions o;
    o.cluster_size_m = 0.1f;
    o.cluster_transfer = transfer;
    o.threads = 2;
    Texturer t(g.rig, o);
    Mesh mesh = g.scene;
    mesh.colors.clear();
    ASSERT_TRUE(t.Apply(g.frames, &mesh).ok());
    ASSERT_EQ(mesh.colors.size(), mesh.num_vertices());
    EXPECT_GT(t.stats().coarse_vertices, 0u);
    EXPECT_LT(t.stats().coarse_vertices, mesh.num_vertices());
    double worst = 0;
    for (size_t v : hidden) worst = std::max(worst, ColorDistance(mesh.colors[v], {240, 240, 240}));
    EXPECT_LT(worst, 12.0) << "transfer " << transfer;
  }
  TextureOptions bad;
  bad.cluster_size_m = -1.0f;
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
  bad.cluster_size_m = 0.01f;
  bad.cluster_transfer = 3;
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
}

TEST(TexturerTest, TexturingTheWallAloneWouldGhost) {
  // Why the occluder must be part of the rasterized mesh: texturing the wall
  // without the bar, the bar in pod A's image lands on the wall.
  const GhostScene g = MakeGhostScene();
  TextureOptions o;
  o.voting_levels = 0;
  o.discontinuity_test = false;
  Texturer t(g.rig, o);
  Mesh wall = g.wall;
  ASSERT_TRUE(t.Apply(g.frames, &wall).ok());
  double mean = 0;
  const std::vector<size_t> hidden = HiddenWallVertices(g);
  for (size_t v : hidden) mean += ColorDistance(wall.colors[v], {240, 240, 240});
  EXPECT_GT(mean / hidden.size(), 60.0);
}

// A green sphere (r = 0.30 m) on a blue background, seen by pod A (+x) and
// pod B (+y). The mesh to texture is inflated by 2 cm, as a reconstruction
// may be: vertices on A's silhouette project onto the blue background in A.
TEST(TexturerTest, DiscontinuityTestExcludesViewsAtSilhouettes) {
  const Vector3f c(0, 0, 1.0f);
  Rig rig;
  rig.name = "sil";
  rig.pods.push_back(MakePod(0, c + Vector3f(2.0f, 0, 0), c));
  rig.pods.push_back(MakePod(1, c + Vector3f(0, 2.0f, 0), c));
  Mesh truth = metrics::MakeSphereMesh(c, 0.30f, 4);
  Paint(&truth, {30, 200, 40});
  const RgbdFrameSet frames = RenderPods(rig, truth, {20, 30, 230});
  Mesh mesh = metrics::MakeSphereMesh(c, 0.32f, 4);

  // Vertices on A's silhouette that B sees head-on.
  std::vector<size_t> rim;
  const Vector3f a = rig.pods[0].ColorCamera().Center(), b = rig.pods[1].ColorCamera().Center();
  for (size_t v = 0; v < mesh.num_vertices(); ++v) {
    const Vector3f n = (mesh.positions[v] - c).normalized();
    const float na = n.dot((a - mesh.positions[v]).normalized());
    const float nb = n.dot((b - mesh.positions[v]).normalized());
    if (na > 0.0f && na < 0.12f && nb > 0.8f) rim.push_back(v);
  }
  ASSERT_GT(rim.size(), 10u);
  auto mean_error = [&](TextureOptions o) {
    o.threads = 1;
    Texturer t(rig, o);
    Mesh m = mesh;
    HOLO_CHECK(t.Apply(frames, &m).ok());
    double e = 0;
    for (size_t v : rim) e += ColorDistance(m.colors[v], {30, 200, 40});
    return e / rim.size();
  };
  for (int voting : {0, 3}) {
    TextureOptions on;
    on.voting_levels = voting;
    on.alpha = 0;  // let A's grazing samples count fully: the test alone must keep them out
    TextureOptions off = on;
    off.discontinuity_test = false;
    const double err_on = mean_error(on), err_off = mean_error(off);
    EXPECT_LT(err_on, 8.0) << "voting " << voting;
    EXPECT_GT(err_off, 30.0) << "voting " << voting;
  }
}

TEST(TexturerTest, UnobservedVerticesAreFilledFromNeighbours) {
  // One pod sees the middle of a plane much larger than its view: vertices
  // outside the image are never observed and are filled from the visible ones.
  Rig rig;
  rig.name = "one";
  rig.pods.push_back(MakePod(0, {0, 0, 1.0f}, {0, 0, 0}, 160, 120, Vector3f::UnitY()));
  Mesh plane = metrics::MakePlaneMesh({0, 0, 0}, 4.0f, 4.0f, 40, 40);  // far larger than the view
  Paint(&plane, {50, 100, 150});
  const RgbdFrameSet frames = RenderPods(rig, plane);
  TextureOptions o;
  Texturer t(rig, o);
  Mesh m = plane;
  m.colors.clear();
  ASSERT_TRUE(t.Apply(frames, &m).ok());
  EXPECT_GT(t.stats().filled_from_neighbours, 0u);
  EXPECT_EQ(t.stats().uncoloured, 0u);
  for (size_t v = 0; v < m.num_vertices(); ++v) EXPECT_LT(ColorDistance(m.colors[v], {50, 100, 150}), 3.0) << v;
}

TEST(TexturerTest, MajorityVotingRejectsAnOutlierView) {
  // Three pods see a patch; pod 2's image is corrupted (as by an occluder the
  // geometry missed). Voting keeps the two agreeing views.
  const Vector3f c(0, 0, 0);
  Rig rig;
  rig.name = "three";
  for (int i = 0; i < 3; ++i) {
    const float a = 0.4f * (i - 1);
    rig.pods.push_back(MakePod(i, {std::sin(a) * 2.0f, 0.0f, std::cos(a) * 2.0f}, c, 160, 120, Vector3f::UnitY()));
  }
  Mesh plane = metrics::MakePlaneMesh(c, 0.5f, 0.5f, 10, 10);
  Paint(&plane, {200, 180, 60});
  RgbdFrameSet frames = RenderPods(rig, plane);
  frames.frames[2].color.Fill(0);  // pod 2 sees black
  TextureOptions o;
  o.alpha = 0;
  Texturer t(rig, o);
  Mesh m = plane;
  ASSERT_TRUE(t.Apply(frames, &m).ok());
  // Interior vertices (the border ones straddle the plane's silhouette in every view).
  for (size_t v = 0; v < m.num_vertices(); ++v) {
    if (m.positions[v].head<2>().cwiseAbs().maxCoeff() < 0.2f) {
      EXPECT_LT(ColorDistance(m.colors[v], {200, 180, 60}), 4.0) << v;
    }
  }
  EXPECT_GT(t.stats().voted, 0u);
  o.voting_levels = 0;
  Texturer plain(rig, o);
  ASSERT_TRUE(plain.Apply(frames, &m).ok());
  EXPECT_GT(ColorDistance(m.colors[m.num_vertices() / 2], {200, 180, 60}), 50.0);
}

TEST(TexturerTest, ForegroundMasksExcludeViews) {
  // Pod 1's image is corrupted but its mask says "background everywhere":
  // with masks in use (default) only pod 0 colours the patch.
  Rig rig;
  rig.name = "two";
  rig.pods.push_back(MakePod(0, {0.3f, 0.0f, 2.0f}, {0, 0, 0}, 160, 120, Vector3f::UnitY()));
  rig.pods.push_back(MakePod(1, {-0.3f, 0.0f, 2.0f}, {0, 0, 0}, 160, 120, Vector3f::UnitY()));
  Mesh plane = metrics::MakePlaneMesh({0, 0, 0}, 0.5f, 0.5f, 10, 10);
  Paint(&plane, {90, 160, 220});
  RgbdFrameSet frames = RenderPods(rig, plane);
  frames.frames[1].color.Fill(255);
  frames.frames[1].mask.Resize(160, 120, 0);
  TextureOptions o;
  o.voting_levels = 0;
  Texturer t(rig, o);
  Mesh m = plane;
  ASSERT_TRUE(t.Apply(frames, &m).ok());
  const size_t centre = m.num_vertices() / 2;
  EXPECT_LT(ColorDistance(m.colors[centre], {90, 160, 220}), 4.0);
  o.use_masks = false;
  Texturer unmasked(rig, o);
  ASSERT_TRUE(unmasked.Apply(frames, &m).ok());
  EXPECT_GT(ColorDistance(m.colors[centre], {90, 160, 220}), 50.0);
}

TEST(TexturerTest, ViewsNearAMaskEdgeCountOnlyWithoutACleanView) {
  // A blue plane seen by two pods. Pod 1's segmentation cut a gap into the
  // plane (mask 0 over columns [60, 70)), and the gap is 2 px too narrow: the
  // 2 px on each side of it show the room (magenta) although the mask says
  // foreground — a segmentation edge two pixels off. Vertices there must take
  // pod 0's clean blue, not the room.
  Rig rig;
  rig.name = "two";
  rig.pods.push_back(MakePod(0, {0.3f, 0.0f, 2.0f}, {0, 0, 0}, 160, 120, Vector3f::UnitY()));
  rig.pods.push_back(MakePod(1, {-0.3f, 0.0f, 2.0f}, {0, 0, 0}, 160, 120, Vector3f::UnitY()));
  Mesh plane = metrics::MakePlaneMesh({0, 0, 0}, 0.5f, 0.5f, 40, 40);
  const Rgb blue = {90, 160, 220};
  Paint(&plane, blue);
  RgbdFrameSet frames = RenderPods(rig, plane);
  ImageRgb8& im = frames.frames[1].color;
  ImageGray8& mask = frames.frames[1].mask;
  mask.Resize(160, 120, 255);
  for (int y = 0; y < 120; ++y)
    for (int x = 58; x < 72; ++x) {
      im.at(x, y, 0) = 255;
      im.at(x, y, 1) = 0;
      im.at(x, y, 2) = 255;
      if (x >= 60 && x < 70) mask.at(x, y) = 0;
    }
  const CameraModel cam1 = rig.pods[1].ColorCamera();
  auto worst = [&](const TextureOptions& o) {
    Texturer t(rig, o);
    Mesh m = plane;
    m.colors.clear();
    EXPECT_TRUE(t.Apply(frames, &m).ok());
    double d = 0;
    int band = 0;
    for (size_t v = 0; v < m.num_vertices(); ++v) {
      Eigen::Vector2f uv;
      if (!cam1.ProjectWorld(m.positions[v], &uv)) continue;
      const int x = static_cast<int>(std::lround(uv.x()));
      if (!((x >= 58 && x < 60) || (x >= 70 && x < 72)) || std::abs(m.positions[v].y()) > 0.2f) continue;
      d = std::max(d, ColorDistance(m.colors[v], blue));
      ++band;
    }
    EXPECT_GT(band, 10);
    return d;
  };
  TextureOptions o;
  o.voting_levels = 0;  // plain weighted average: the room's share is visible
  const double now = worst(o);
  o.mask_edge_px = 0;  // the texturer before issue 17
  const double old = worst(o);
  std::printf("worst colour error in the band: %.1f now, %.1f with mask_edge_px = 0\n", now, old);
  EXPECT_GT(old, 40.0);
  EXPECT_LT(now, 8.0);
}

TEST(TexturerTest, ResultIndependentOfThreadCountAndRepeatable) {
  const GhostScene g = MakeGhostScene();
  std::vector<std::vector<Rgb>> results;
  for (int threads : {1, 2, 3}) {
    TextureOptions o;
    o.threads = threads;
    Texturer t(g.rig, o);
    Mesh m = g.scene;
    ASSERT_TRUE(t.Apply(g.frames, &m).ok());
    ASSERT_TRUE(t.Apply(g.frames, &m).ok());  // reused buffers
    results.push_back(m.colors);
  }
  EXPECT_EQ(results[0], results[1]);
  EXPECT_EQ(results[0], results[2]);
}

TEST(TexturerTest, SteadyStateApplyDoesNotAllocate) {
  const GhostScene g = MakeGhostScene();
  TextureOptions o;
  o.threads = 2;
  Texturer t(g.rig, o);
  Mesh m = g.scene;
  ASSERT_TRUE(t.Apply(g.frames, &m).ok());  // sizes the buffers
  const size_t before = g_allocations.load();
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(t.Apply(g.frames, &m).ok());
  EXPECT_EQ(g_allocations.load() - before, 0u);
}

TEST(TexturerTest, BadInputsGiveErrors) {
  const GhostScene g = MakeGhostScene();
  Mesh m = g.scene;
  {
    TextureOptions o;
    o.alpha = -1;
    EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
    Texturer t(g.rig, o);
    const Status s = t.Apply(g.frames, &m);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find("alpha"), std::string::npos) << s.message();
  }
  for (auto bad : {&TextureOptions::discontinuity_radius_m, &TextureOptions::discontinuity_jump_m,
                   &TextureOptions::visibility_tolerance_m, &TextureOptions::vote_threshold}) {
    TextureOptions o;
    o.*bad = -0.5f;
    EXPECT_EQ(o.Check().code(), StatusCode::kInvalidArgument);
  }
  TextureOptions levels;
  levels.voting_levels = -1;
  EXPECT_EQ(levels.Check().code(), StatusCode::kInvalidArgument);

  Texturer t(g.rig, TextureOptions{});
  EXPECT_EQ(t.Apply(g.frames, nullptr).code(), StatusCode::kInvalidArgument);
  RgbdFrameSet one = g.frames;
  one.frames.pop_back();
  Status s = t.Apply(one, &m);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("1 frames for a rig of 2 pods"), std::string::npos) << s.message();
  RgbdFrameSet small = g.frames;
  small.frames[1].color.Resize(10, 10);
  s = t.Apply(small, &m);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("pod 1"), std::string::npos) << s.message();
  RgbdFrameSet bad_mask = g.frames;
  bad_mask.frames[0].mask.Resize(3, 3);
  EXPECT_EQ(t.Apply(bad_mask, &m).code(), StatusCode::kInvalidArgument);
  Mesh broken = g.scene;
  broken.triangles.push_back({0, 1, 99999999});
  EXPECT_EQ(t.Apply(g.frames, &broken).code(), StatusCode::kDataLoss);
  Rig empty;
  empty.name = "empty";
  Texturer none(empty, TextureOptions{});
  EXPECT_EQ(none.Apply(RgbdFrameSet{}, &m).code(), StatusCode::kInvalidArgument);
}

// ------------------------------------------------- studio ground-truth mesh

TEST(TexturerTest, StudioGroundTruthMeshRecoversColoursAndNovelViews) {
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok()) << workload.status().ToString();
  StudioOptions so = workload->studio;
  so.color_variation = false;
  so.threads = 2;
  auto studio = SyntheticStudio::Create(workload->rig, so);
  ASSERT_TRUE(studio.ok());
  RgbdFrameSet set;
  StudioGroundTruth gt;
  const int64_t frame = 40;
  (*studio)->RenderFrame(frame, &set, &gt);

  NovelViewOptions nvo;
  nvo.intrinsics = workload->rig.pods[0].color;
  const std::vector<NovelView> views = MakeNovelViews(nvo);

  // Reference colour per vertex, independent of the texturer: the lit colour
  // (the studio shades Lambert + ambient, view-independent) sampled in the
  // most frontal pod whose noise-free depth confirms the vertex is visible
  // there, away from the true mask's edges.
  const Mesh& truth = gt.foreground_mesh;
  std::vector<std::array<float, 3>> reference(truth.num_vertices());
  std::vector<uint8_t> has_reference(truth.num_vertices(), 0);
  for (size_t v = 0; v < truth.num_vertices(); ++v) {
    float best = 0.3f;
    for (size_t pi = 0; pi < workload->rig.pods.size(); ++pi) {
      const CameraModel cam = workload->rig.pods[pi].ColorCamera();
      const Vector3f pc = cam.world_from_camera.inverse() * truth.positions[v];
      Eigen::Vector2f uv;
      if (!cam.ProjectCamera(pc, &uv)) continue;
      const int x = static_cast<int>(std::lround(uv.x())), y = static_cast<int>(std::lround(uv.y()));
      if (x < 2 || y < 2 || x >= cam.intrinsics.width - 2 || y >= cam.intrinsics.height - 2) continue;
      if (std::abs(gt.depth[pi].at(x, y) - pc.z() * 1000.0f) > 10.0f) continue;
      bool interior = true;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) interior = interior && gt.mask[pi].at(x + dx, y + dy) != 0;
      const float ndv = truth.normals[v].normalized().dot((cam.Center() - truth.positions[v]).normalized());
      if (!interior || ndv <= best) continue;
      best = ndv;
      has_reference[v] = 1;
      const ImageRgb8& img = set.frames[pi].color;
      for (int c = 0; c < 3; ++c) reference[v][c] = img.at(x, y, c);
    }
  }

  auto run = [&](TextureOptions o, double* color_mae, double* psnr) {
    o.threads = 2;
    Texturer t(workload->rig, o);
    Mesh mesh = truth;
    mesh.colors.clear();
    ASSERT_TRUE(t.Apply(set, &mesh).ok());
    double sum = 0;
    size_t n = 0;
    for (size_t v = 0; v < mesh.num_vertices(); ++v) {
      if (!has_reference[v]) continue;
      for (int c = 0; c < 3; ++c) sum += std::abs(mesh.colors[v][c] - reference[v][c]);
      n += 3;
    }
    ASSERT_GT(n, 3 * truth.num_vertices() / 3);
    *color_mae = sum / n;
    double p = 0;
    for (const NovelView& view : views) {
      auto score = ScoreNovelView(**studio, frame, mesh, view);
      ASSERT_TRUE(score.ok()) << score.status().ToString();
      p += score->psnr_db;
    }
    *psnr = p / views.size();
  };
  double mae = 0, psnr = 0, naive_mae = 0, naive_psnr = 0;
  run(TextureOptions{}, &mae, &psnr);
  TextureOptions naive;
  naive.visibility_test = naive.discontinuity_test = naive.normal_weighting = false;
  naive.voting_levels = 0;
  run(naive, &naive_mae, &naive_psnr);
  std::printf("ground-truth mesh, frame %lld: colour MAE vs reference %.2f (naive %.2f), novel-view PSNR %.2f dB (naive %.2f)\n",
              static_cast<long long>(frame), mae, naive_mae, psnr, naive_psnr);
  // Measured on this frame: MAE 6.0 (naive 24.5) per channel, PSNR 22.5 dB
  // (naive 17.6). Per-vertex colour on a 7.7k-vertex figure cannot hold the
  // shirt stripes and trouser checks at full detail, hence ~22 dB even with
  // exact geometry; bounds leave a margin.
  EXPECT_LT(mae, 8.0);
  EXPECT_GT(psnr, 21.5);
  EXPECT_LT(mae, naive_mae / 2);
  EXPECT_GT(psnr, naive_psnr + 3.0);
}

}  // namespace
}  // namespace holo
