// The projective-texturing atlas bake (client/render/atlas.h), on the CPU
// without GL: every texel of a plane seen by a pod takes the pod's colour at
// the texel's surface point; hidden points, depth discontinuities and weak
// mask weights behave as the renderer's shaders do; the layout keeps each
// triangle in its own cell; threads do not change the result; bad input is
// refused with a reason.
#include <array>
#include <cmath>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "client/render/atlas.h"
#include "common/camera.h"
#include "common/worker_pool.h"

namespace holo::render {
namespace {

constexpr int kW = 64, kH = 48;

// A pod at the origin looking along +z, its image a linear gradient
// (R = 2u, G = 3v: bilinear sampling reproduces it exactly), every pixel
// seeing a surface at `z` (flagged negative when `edge`).
struct TestPod {
  CameraModel camera;
  std::vector<float> z;
  std::vector<uint8_t> rgba;
  TestPod(float depth, bool edge, uint8_t alpha, std::array<uint8_t, 3> flat = {0, 0, 0}, bool gradient = true) {
    camera.intrinsics = Intrinsics::FromFov(kW, kH, 60.0);
    camera.world_from_camera = Eigen::Isometry3f::Identity();
    z.assign(kW * kH, edge ? -depth : depth);
    rgba.resize(4 * kW * kH);
    for (int v = 0; v < kH; ++v) {
      for (int u = 0; u < kW; ++u) {
        uint8_t* p = &rgba[4 * (v * kW + u)];
        const int r = gradient ? 2 * u : flat[0], g = gradient ? 3 * v : flat[1], b = gradient ? 50 : flat[2];
        // Premultiplied by alpha, as the renderer uploads them.
        p[0] = static_cast<uint8_t>((r * alpha + 127) / 255);
        p[1] = static_cast<uint8_t>((g * alpha + 127) / 255);
        p[2] = static_cast<uint8_t>((b * alpha + 127) / 255);
        p[3] = alpha;
      }
    }
  }
  AtlasPod View() const { return {&camera, z.data(), rgba.data()}; }
};

// An n×n grid of quads (2 triangles each) on the plane z = `depth`, x and y
// in [−half, half], facing the origin, grey vertex colour 100.
struct TestMesh {
  std::vector<Eigen::Vector3f> positions, normals;
  std::vector<std::array<uint8_t, 3>> colors;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<uint16_t> vertex_pods, triangle_pods;
  TestMesh(int n, float half, float depth, uint16_t pods) {
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i <= n; ++i) {
        positions.push_back({-half + 2 * half * i / n, -half + 2 * half * j / n, depth});
        normals.push_back({0, 0, -1});
        colors.push_back({100, 100, 100});
      }
    }
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
        triangles.push_back({a, b, d});
        triangles.push_back({a, d, c});
      }
    }
    vertex_pods.assign(positions.size(), pods);
    triangle_pods.assign(triangles.size(), pods);
  }
  AtlasMeshInput Input() const { return {&positions, &normals, &colors, &triangles, &vertex_pods, &triangle_pods}; }
};

// Calls fn(triangle, i, j, l, point, texel) for every texel on every
// triangle (i + j ≤ l), the texel's surface point from its barycentrics.
template <typename F>
void ForEachTexel(const TestMesh& m, const Atlas& atlas, F&& fn) {
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    const auto& uv = atlas.uv;
    const int x0 = static_cast<int>(std::lround(uv[3 * t][0] * atlas.width - 0.5f));
    const int y0 = static_cast<int>(std::lround(uv[3 * t][1] * atlas.height - 0.5f));
    const int l = static_cast<int>(std::lround(uv[3 * t + 1][0] * atlas.width - 0.5f)) - x0;
    ASSERT_GE(l, 1);
    ASSERT_EQ(static_cast<int>(std::lround(uv[3 * t + 2][1] * atlas.height - 0.5f)) - y0, l);
    for (int j = 0; j <= l; ++j) {
      for (int i = 0; i + j <= l; ++i) {
        const float b1 = static_cast<float>(i) / l, b2 = static_cast<float>(j) / l, b0 = 1 - b1 - b2;
        const auto& tri = m.triangles[t];
        const Eigen::Vector3f p = b0 * m.positions[tri[0]] + b1 * m.positions[tri[1]] + b2 * m.positions[tri[2]];
        const uint8_t* texel = &atlas.rgba[4 * (static_cast<size_t>(y0 + j) * atlas.width + x0 + i)];
        fn(t, i, j, l, p, texel);
      }
    }
  }
}

TEST(AtlasTest, EveryTexelTakesThePodsColourAtItsSurfacePoint) {
  const TestPod pod(2.0f, false, 255);
  const TestMesh mesh(6, 0.5f, 2.0f, 0x1);
  AtlasBakeOptions o;
  o.texels_per_edge = 4;
  o.texels_per_pod_pixel = 0;  // always texels_per_edge
  Atlas atlas;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  EXPECT_GT(atlas.width, 0);
  EXPECT_EQ(atlas.rgba.size(), static_cast<size_t>(atlas.width) * atlas.height * 4);
  int checked = 0;
  ForEachTexel(mesh, atlas, [&](size_t, int, int, int l, const Eigen::Vector3f& p, const uint8_t* texel) {
    EXPECT_EQ(l, o.texels_per_edge);
    Eigen::Vector2f px;
    ASSERT_TRUE(pod.camera.ProjectWorld(p, &px));
    EXPECT_NEAR(texel[0], 2 * px.x(), 1.01) << p.transpose();
    EXPECT_NEAR(texel[1], 3 * px.y(), 1.01) << p.transpose();
    EXPECT_NEAR(texel[2], 50, 1);
    EXPECT_EQ(texel[3], 255);
    ++checked;
  });
  // 72 triangles × 15 texels on each (L = 4).
  EXPECT_EQ(checked, 72 * 15);
  EXPECT_EQ(atlas.samples, atlas.texels_baked);  // one pod, every texel in view
}

TEST(AtlasTest, HiddenPointsTakeTheVertexColour) {
  // The pod's depth map shows a surface 10 cm in front of the plane.
  const TestPod pod(1.9f, false, 255);
  const TestMesh mesh(2, 0.3f, 2.0f, 0x1);
  Atlas atlas;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, {}, nullptr, &atlas).ok());
  ForEachTexel(mesh, atlas, [&](size_t, int, int, int, const Eigen::Vector3f&, const uint8_t* texel) {
    EXPECT_EQ(texel[0], 100);
    EXPECT_EQ(texel[1], 100);
    EXPECT_EQ(texel[2], 100);
  });
}

TEST(AtlasTest, DiscontinuitySamplesCountOnlyWhereNothingCleanIs) {
  const TestPod red_edge(2.0f, /*edge=*/true, 255, {220, 0, 0}, false);
  const TestPod blue_clean(2.0f, false, 255, {0, 0, 220}, false);
  const TestMesh mesh(2, 0.3f, 2.0f, 0x3);
  Atlas both, edge_only;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {red_edge.View(), blue_clean.View()}, {}, nullptr, &both).ok());
  TestMesh only_red = mesh;
  only_red.vertex_pods.assign(only_red.vertex_pods.size(), 0x1);
  only_red.triangle_pods.assign(only_red.triangle_pods.size(), 0x1);
  ASSERT_TRUE(BakeAtlas(only_red.Input(), {red_edge.View(), blue_clean.View()}, {}, nullptr, &edge_only).ok());
  ForEachTexel(mesh, both, [&](size_t, int, int, int, const Eigen::Vector3f&, const uint8_t* texel) {
    EXPECT_LE(texel[0], 1);
    EXPECT_GE(texel[2], 219);
  });
  ForEachTexel(only_red, edge_only, [&](size_t, int, int, int, const Eigen::Vector3f&, const uint8_t* texel) {
    EXPECT_GE(texel[0], 219);
    EXPECT_LE(texel[2], 1);
  });
}

TEST(AtlasTest, WeakMaskWeightFadesToTheVertexColour) {
  // Every sample at a mask edge (weight 0.1 < min_mask_confidence 0.5).
  const TestPod weak(2.0f, false, 26, {220, 220, 0}, false);
  const TestMesh mesh(2, 0.3f, 2.0f, 0x1);
  AtlasBakeOptions o;
  Atlas faded, plain;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {weak.View()}, o, nullptr, &faded).ok());
  o.min_mask_confidence = 0;  // never fade (a mesh without vertex colours)
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {weak.View()}, o, nullptr, &plain).ok());
  ForEachTexel(mesh, faded, [&](size_t, int, int, int, const Eigen::Vector3f&, const uint8_t* texel) {
    // smoothstep(0, 0.5, 0.1) = 0.104: mostly the vertex colour 100.
    EXPECT_NEAR(texel[0], 100 + 0.104 * 120, 4);
    EXPECT_NEAR(texel[2], 100 - 0.104 * 100, 4);
  });
  ForEachTexel(mesh, plain, [&](size_t, int, int, int, const Eigen::Vector3f&, const uint8_t* texel) {
    EXPECT_NEAR(texel[0], 220, 6);  // 8-bit premultiplication at alpha 26
    EXPECT_LE(texel[2], 1);
  });
}

TEST(AtlasTest, CellsAreDisjointAndThreadsDoNotChangeTheResult) {
  const TestPod pod(2.0f, false, 255);
  const TestMesh mesh(20, 0.5f, 2.0f, 0x1);  // 800 triangles
  AtlasBakeOptions o;
  o.max_width = 64;  // several rows of cells
  Atlas one, two;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &one).ok());
  WorkerPool pool(2);
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, &pool, &two).ok());
  EXPECT_EQ(one.rgba, two.rgba);
  EXPECT_EQ(one.uv, two.uv);
  EXPECT_LE(one.width, 64);
  std::set<std::pair<int, int>> cells;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_GT(one.uv[3 * t + k][0], 0.0f);
      EXPECT_LT(one.uv[3 * t + k][0], 1.0f);
      EXPECT_GT(one.uv[3 * t + k][1], 0.0f);
      EXPECT_LT(one.uv[3 * t + k][1], 1.0f);
    }
    const int cell = o.texels_per_edge + 1;
    cells.insert({static_cast<int>(one.uv[3 * t][0] * one.width) / cell,
                  static_cast<int>(one.uv[3 * t][1] * one.height) / cell});
  }
  EXPECT_EQ(cells.size(), mesh.triangles.size());
}

TEST(AtlasTest, SmallTrianglesGetFewerTexels) {
  const TestPod pod(2.0f, false, 255);
  // Triangle legs of 1 cm: about 0.28 pod pixels at 2 m.
  const TestMesh mesh(10, 0.05f, 2.0f, 0x1);
  AtlasBakeOptions o;
  o.texels_per_edge = 4;
  Atlas atlas;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  ForEachTexel(mesh, atlas, [&](size_t, int, int, int l, const Eigen::Vector3f&, const uint8_t*) { EXPECT_EQ(l, 1); });
  // l = 1: the 3 corners plus the texel past the third edge.
  EXPECT_EQ(atlas.texels_baked, 4 * mesh.triangles.size());
  o.texels_per_pod_pixel = 0;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  EXPECT_EQ(atlas.texels_baked, 19 * mesh.triangles.size());  // L = 4: 15 on the triangle + 4 past it
}

TEST(AtlasTest, TrianglesLargeInTheirPodGetUpToEightTexelsPerEdge) {
  const TestPod pod(2.0f, false, 255);
  // Legs of 0.5 m at 2 m: about 14 pod pixels, more than 8.
  const TestMesh mesh(2, 0.5f, 2.0f, 0x1);
  AtlasBakeOptions o;  // the default, as the viewer bakes
  Atlas atlas;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  int checked = 0;
  ForEachTexel(mesh, atlas, [&](size_t, int, int, int l, const Eigen::Vector3f&, const uint8_t*) {
    EXPECT_EQ(l, 8);
    ++checked;
  });
  EXPECT_EQ(checked, 8 * 45);  // 8 triangles × 45 texels on each (L = 8)
}

TEST(AtlasTest, AMeshTooLargeForTheAtlasGetsFewerTexelsBeforeItIsRefused) {
  const TestPod pod(2.0f, false, 255);
  const TestMesh mesh(6, 0.5f, 2.0f, 0x1);  // 72 triangles
  AtlasBakeOptions o;
  o.texels_per_pod_pixel = 0;  // always L
  o.max_width = 45;            // 5 cells of L = 8 per row: 15 rows of 9 = 135 texels
  o.max_height = 100;          // L = 4: 9 cells per row, 8 rows of 5 = 40
  Atlas atlas;
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  EXPECT_EQ(atlas.texels_per_edge, 4);
  EXPECT_LE(atlas.height, 100);
  int checked = 0;
  ForEachTexel(mesh, atlas, [&](size_t, int, int, int l, const Eigen::Vector3f& p, const uint8_t* texel) {
    EXPECT_EQ(l, 4);
    Eigen::Vector2f px;
    ASSERT_TRUE(pod.camera.ProjectWorld(p, &px));
    EXPECT_NEAR(texel[0], 2 * px.x(), 1.01);
    ++checked;
  });
  EXPECT_EQ(checked, 72 * 15);
  // Room for one texel per edge only (L = 2 needs 5 rows of 3), and less: refused.
  o.max_height = 10;  // L = 1: 22 cells per row, 4 rows of 2 = 8
  ASSERT_TRUE(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).ok());
  EXPECT_EQ(atlas.texels_per_edge, 1);
  o.max_height = 7;
  EXPECT_EQ(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).code(), StatusCode::kOutOfRange);
}

// The AVX2 sampling loop against the portable one on a scene that reaches
// every branch: three pods at different poses, depth maps with empty,
// flagged, nearer and farther pixels, colours with every mask weight, a
// bumpy mesh that runs past the images' borders, and cells of every size.
TEST(AtlasTest, VectorisedBakeMatchesThePortableLoop) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<TestPod> pods;
  for (int k = 0; k < 3; ++k) {
    TestPod pod(2.0f, false, 255);
    const float yaw = 0.35f * static_cast<float>(k - 1);
    pod.camera.world_from_camera = Eigen::Translation3f(1.9f * std::sin(yaw), 0.1f * k, 2.0f - 2.0f * std::cos(yaw)) *
                                   Eigen::AngleAxisf(-yaw, Eigen::Vector3f::UnitY());
    for (size_t i = 0; i < pod.z.size(); ++i) {
      const float r = unit(rng);
      float z = 2.0f + 0.02f * (unit(rng) - 0.5f);
      if (r < 0.1f) z = 0.0f;           // empty
      else if (r < 0.2f) z = -z;         // near a discontinuity
      else if (r < 0.3f) z -= 0.1f;      // something in front
      pod.z[i] = z;
      const uint8_t a = static_cast<uint8_t>(rng() % 256);
      for (int c = 0; c < 3; ++c) pod.rgba[4 * i + c] = static_cast<uint8_t>((rng() % 256) * a / 255);
      pod.rgba[4 * i + 3] = a;
    }
    pods.push_back(std::move(pod));
  }
  TestMesh mesh(40, 1.6f, 2.0f, 0x7);
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    mesh.positions[v].z() += 0.05f * (unit(rng) - 0.5f);
    mesh.normals[v] = Eigen::Vector3f(unit(rng) - 0.5f, unit(rng) - 0.5f, -1.0f).normalized();
    mesh.vertex_pods[v] = static_cast<uint16_t>(rng() % 8);
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) mesh.triangle_pods[t] = static_cast<uint16_t>(1 + rng() % 7);
  std::vector<AtlasPod> views;
  for (const auto& p : pods) views.push_back(p.View());
  for (float density : {0.0f, 1.0f, 3.0f}) {
    AtlasBakeOptions o;
    o.texels_per_pod_pixel = density;
    o.texels_per_edge = 6;
    Atlas portable, vectorised;
    o.vectorized = false;
    ASSERT_TRUE(BakeAtlas(mesh.Input(), views, o, nullptr, &portable).ok());
    o.vectorized = true;
    ASSERT_TRUE(BakeAtlas(mesh.Input(), views, o, nullptr, &vectorised).ok());
    SCOPED_TRACE(density);
    EXPECT_GT(portable.samples, 10000u);
    EXPECT_LT(portable.samples, portable.texels_baked * 3);  // some fall outside the images
    EXPECT_EQ(portable.samples, vectorised.samples);
    EXPECT_EQ(portable.texels_baked, vectorised.texels_baked);
    EXPECT_EQ(portable.uv, vectorised.uv);
    ASSERT_EQ(portable.rgba.size(), vectorised.rgba.size());
    size_t differ = 0;
    for (size_t i = 0; i < portable.rgba.size(); ++i) differ += portable.rgba[i] != vectorised.rgba[i];
    EXPECT_EQ(differ, 0u);
  }
}

TEST(AtlasTest, BadInputIsRefusedWithAReason) {
  const TestPod pod(2.0f, false, 255);
  TestMesh mesh(2, 0.3f, 2.0f, 0x1);
  Atlas atlas;
  AtlasBakeOptions o;
  o.texels_per_edge = 0;
  EXPECT_EQ(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).code(), StatusCode::kInvalidArgument);
  o = {};
  o.texels_per_pod_pixel = -1;
  EXPECT_EQ(BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas).code(), StatusCode::kInvalidArgument);
  o = {};
  o.texels_per_edge = 4;
  o.max_width = 10;
  o.max_height = 3;  // 8 triangles: 4 rows of 5 (L = 4), 3 of 3 (L = 2), 2 of 2 (L = 1): all > 3
  const Status too_big = BakeAtlas(mesh.Input(), {pod.View()}, o, nullptr, &atlas);
  EXPECT_EQ(too_big.code(), StatusCode::kOutOfRange);
  EXPECT_NE(too_big.message().find("triangles"), std::string::npos) << too_big.message();
  mesh.triangle_pods.pop_back();
  const Status sizes = BakeAtlas(mesh.Input(), {pod.View()}, {}, nullptr, &atlas);
  EXPECT_EQ(sizes.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(sizes.message().find("triangle pod sets"), std::string::npos) << sizes.message();
  TestMesh ok(2, 0.3f, 2.0f, 0x1);
  AtlasPod missing = pod.View();
  missing.rgba = nullptr;
  EXPECT_EQ(BakeAtlas(ok.Input(), {missing}, {}, nullptr, &atlas).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace holo::render
