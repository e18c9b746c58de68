// Tests of common/metrics: closest-point index, surface sampling, mesh
// distance, image metrics, mask overlap and temporal flicker.
#include <cmath>
#include <cstdio>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "common/metrics/flicker.h"
#include "common/metrics/image_metrics.h"
#include "common/metrics/mesh_distance.h"
#include "common/metrics/mesh_shapes.h"
#include "common/metrics/surface_sampling.h"
#include "common/metrics/triangle_index.h"
#include "test_util.h"

namespace holo::metrics {
namespace {

constexpr double kPi = 3.14159265358979323846;

Mesh Transformed(const Mesh& mesh, const Eigen::Affine3f& t) {
  Mesh out = mesh;
  for (auto& p : out.positions) p = t * p;
  out.normals.clear();
  return out;
}

Mesh Scaled(const Mesh& mesh, const Eigen::Vector3f& scale) {
  Eigen::Affine3f t = Eigen::Affine3f::Identity();
  t.scale(scale);
  return Transformed(mesh, t);
}

// A closed sphere plus a soup of random (some degenerate) triangles.
Mesh RandomTestMesh(uint32_t seed) {
  Mesh mesh = MakeSphereMesh(Eigen::Vector3f(0.1f, 0, 0), 0.3f, 3);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.6f, 0.6f);
  for (int i = 0; i < 300; ++i) {
    const uint32_t base = static_cast<uint32_t>(mesh.positions.size());
    const Eigen::Vector3f a(u(rng), u(rng), u(rng));
    mesh.positions.push_back(a);
    mesh.positions.push_back(a + 0.1f * Eigen::Vector3f(u(rng), u(rng), u(rng)));
    if (i % 25 == 0) {
      mesh.positions.push_back(mesh.positions[base + 1]);  // degenerate: two equal vertices
    } else if (i % 25 == 1) {
      mesh.positions.push_back(a + 2.0f * (mesh.positions[base + 1] - a));  // degenerate: collinear
    } else {
      mesh.positions.push_back(a + 0.1f * Eigen::Vector3f(u(rng), u(rng), u(rng)));
    }
    mesh.triangles.push_back({base, base + 1, base + 2});
  }
  mesh.normals.clear();
  return mesh;
}

// Sphere `mesh` without the triangles whose centroid has z > `z_cut`; writes
// the removed fraction of the area.
Mesh WithoutCap(const Mesh& mesh, float z_cut, double* removed_fraction) {
  Mesh out = mesh;
  out.triangles.clear();
  for (const auto& t : mesh.triangles) {
    const float cz = (mesh.positions[t[0]].z() + mesh.positions[t[1]].z() + mesh.positions[t[2]].z()) / 3;
    if (cz <= z_cut) out.triangles.push_back(t);
  }
  *removed_fraction = 1.0 - MeshSurfaceArea(out) / MeshSurfaceArea(mesh);
  return out;
}

MeshDistanceOptions FastOptions() {
  MeshDistanceOptions o;
  o.sampling.num_samples = 20000;
  return o;
}

// ---------------------------------------------------------------------------
// Shapes

TEST(MeshShapesTest, IcosphereCountsAreaAndOrientation) {
  const Mesh s = MakeSphereMesh(Eigen::Vector3f(1, 2, 3), 0.5f, 4);
  EXPECT_EQ(s.num_triangles(), 20u * 256u);
  EXPECT_EQ(s.num_vertices(), 10u * 256u + 2u);
  ASSERT_TRUE(ValidateGeometry(s).ok());
  EXPECT_NEAR(MeshSurfaceArea(s), 4 * kPi * 0.25, 0.01);
  for (const auto& t : s.triangles) {
    const Eigen::Vector3f& a = s.positions[t[0]];
    const Eigen::Vector3f n = (s.positions[t[1]] - a).cross(s.positions[t[2]] - a);
    ASSERT_GT(n.dot(a - Eigen::Vector3f(1, 2, 3)), 0) << "triangle faces inwards";
  }
  for (size_t i = 0; i < s.num_vertices(); ++i)
    EXPECT_NEAR((s.positions[i] - Eigen::Vector3f(1, 2, 3)).norm(), 0.5f, 1e-6f);
}

TEST(MeshShapesTest, UvSphereBoxAndPlane) {
  const Mesh uv = MakeUvSphereMesh(Eigen::Vector3f::Zero(), 1.0f, 32, 64);
  EXPECT_EQ(uv.num_triangles(), 2u * 64u * 31u);
  EXPECT_NEAR(MeshSurfaceArea(uv), 4 * kPi, 0.05);
  for (const auto& t : uv.triangles) {
    const Eigen::Vector3f& a = uv.positions[t[0]];
    ASSERT_GT((uv.positions[t[1]] - a).cross(uv.positions[t[2]] - a).dot(a + uv.positions[t[1]] + uv.positions[t[2]]),
              0);
  }
  const Mesh box = MakeBoxMesh(Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(1, 2, 3), 3);
  EXPECT_EQ(box.num_triangles(), 6u * 9u * 2u);
  EXPECT_NEAR(MeshSurfaceArea(box), 2 * (1 * 2 + 2 * 3 + 3 * 1), 1e-4);
  for (const auto& t : box.triangles) {
    const Eigen::Vector3f& a = box.positions[t[0]];
    const Eigen::Vector3f c = (a + box.positions[t[1]] + box.positions[t[2]]) / 3 - Eigen::Vector3f(0, 0, 1);
    ASSERT_GT((box.positions[t[1]] - a).cross(box.positions[t[2]] - a).dot(c), 0);
  }
  const Mesh plane = MakePlaneMesh(Eigen::Vector3f::Zero(), 2, 1, 4, 2);
  EXPECT_EQ(plane.num_triangles(), 16u);
  EXPECT_NEAR(MeshSurfaceArea(plane), 2.0, 1e-6);
}

// ---------------------------------------------------------------------------
// TriangleIndex

TEST(TriangleIndexTest, MatchesBruteForceOnRandomQueries) {
  const Mesh mesh = RandomTestMesh(7);
  auto index = TriangleIndex::Build(mesh);
  ASSERT_TRUE(index.ok()) << index.status().ToString();
  EXPECT_EQ(index->num_triangles(), mesh.num_triangles());
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-0.9f, 0.9f);
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3f p(u(rng), u(rng), u(rng));
    const ClosestPoint fast = index->Query(p);
    const ClosestPoint slow = index->QueryBruteForce(p);
    ASSERT_TRUE(fast.found());
    ASSERT_NEAR(fast.distance, slow.distance, 1e-6f) << "query " << i;
    EXPECT_NEAR((fast.point - p).norm(), fast.distance, 1e-5f);
    // The closest point is the barycentric combination on the reported triangle.
    const auto& t = mesh.triangles[fast.triangle];
    const Eigen::Vector3f& w = fast.barycentric;
    EXPECT_NEAR(w.sum(), 1.0f, 1e-5f);
    EXPECT_GE(w.minCoeff(), -1e-6f);
    const Eigen::Vector3f q = w[0] * mesh.positions[t[0]] + w[1] * mesh.positions[t[1]] + w[2] * mesh.positions[t[2]];
    EXPECT_LT((q - fast.point).norm(), 1e-5f);
  }
}

TEST(TriangleIndexTest, MaxDistanceEmptyAndInvalid) {
  const Mesh plane = MakePlaneMesh(Eigen::Vector3f::Zero(), 1, 1, 4, 4);
  auto index = TriangleIndex::Build(plane);
  ASSERT_TRUE(index.ok());
  const Eigen::Vector3f p(0.1f, 0.2f, 0.05f);
  const ClosestPoint hit = index->Query(p);
  ASSERT_TRUE(hit.found());
  EXPECT_NEAR(hit.distance, 0.05f, 1e-6f);
  EXPECT_LT((hit.point - Eigen::Vector3f(0.1f, 0.2f, 0)).norm(), 1e-6f);
  EXPECT_FALSE(index->Query(p, 0.04f).found());
  EXPECT_TRUE(index->Query(p, 0.06f).found());
  // Outside the rectangle: closest point on the border.
  EXPECT_NEAR(index->Query(Eigen::Vector3f(0.8f, 0, 0)).distance, 0.3f, 1e-6f);

  auto empty = TriangleIndex::Build(Mesh());
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
  EXPECT_FALSE(empty->Query(p).found());
  EXPECT_TRUE(std::isinf(empty->Query(p).distance));

  Mesh broken = plane;
  broken.triangles.push_back({0, 1, 999});
  auto bad = TriangleIndex::Build(broken);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kDataLoss);
}

TEST(TriangleIndexTest, BatchIsIndependentOfThreadCount) {
  const Mesh mesh = RandomTestMesh(3);
  auto index = TriangleIndex::Build(mesh);
  ASSERT_TRUE(index.ok());
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-0.7f, 0.7f);
  std::vector<Eigen::Vector3f> points(5000);
  for (auto& p : points) p = Eigen::Vector3f(u(rng), u(rng), u(rng));
  const auto one = index->QueryBatch(points, 1e9f, 1);
  const auto two = index->QueryBatch(points, 1e9f, 2);
  const auto three = index->QueryBatch(points, 1e9f, 3);
  for (size_t i = 0; i < points.size(); ++i) {
    ASSERT_EQ(one[i].triangle, two[i].triangle);
    ASSERT_EQ(one[i].triangle, three[i].triangle);
    ASSERT_EQ(one[i].distance, two[i].distance);
    ASSERT_EQ(one[i].distance, three[i].distance);
  }
}

// ---------------------------------------------------------------------------
// Sampling

TEST(SurfaceSamplingTest, AreaWeightedAndDeterministic) {
  // Two triangles of area 0.5 and 1.5.
  Mesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 0, 0}, {8, 0, 0}, {5, 1, 0}};
  mesh.triangles = {{0, 1, 2}, {3, 4, 5}};
  SamplingOptions o;
  o.num_samples = 40000;
  auto s = SampleSurface(mesh, o);
  ASSERT_TRUE(s.ok());
  ASSERT_EQ(s->size(), 40000u);
  size_t first = 0;
  for (const auto& x : *s) {
    first += x.triangle == 0;
    ASSERT_NEAR(x.barycentric.sum(), 1.0f, 1e-5f);
    ASSERT_GE(x.barycentric.minCoeff(), 0.0f);
  }
  EXPECT_NEAR(static_cast<double>(first) / 40000, 0.25, 0.01);
  // Uniform inside a triangle: the mean position is the centroid.
  const auto pos = SamplePositions(mesh, *s);
  Eigen::Vector3d mean_first = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < pos.size(); ++i)
    if ((*s)[i].triangle == 0) mean_first += pos[i].cast<double>();
  mean_first /= static_cast<double>(first);
  EXPECT_NEAR(mean_first.x(), 1.0 / 3, 0.01);
  EXPECT_NEAR(mean_first.y(), 1.0 / 3, 0.01);

  auto again = SampleSurface(mesh, o);
  ASSERT_TRUE(again.ok());
  for (size_t i = 0; i < s->size(); ++i) {
    ASSERT_EQ((*s)[i].triangle, (*again)[i].triangle);
    ASSERT_EQ((*s)[i].barycentric, (*again)[i].barycentric);
  }
  o.seed = 2;
  auto other = SampleSurface(mesh, o);
  ASSERT_TRUE(other.ok());
  EXPECT_NE((*s)[0].barycentric, (*other)[0].barycentric);

  o.samples_per_m2 = 1000;  // area 2 m² → 2000 samples
  EXPECT_EQ(SampleSurface(mesh, o)->size(), 2000u);
  o.max_samples = 500;
  EXPECT_EQ(SampleSurface(mesh, o)->size(), 500u);
}

TEST(SurfaceSamplingTest, Errors) {
  EXPECT_EQ(SampleSurface(Mesh(), {}).status().code(), StatusCode::kInvalidArgument);
  Mesh degenerate;
  degenerate.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  degenerate.triangles = {{0, 1, 2}};
  EXPECT_EQ(SampleSurface(degenerate, {}).status().code(), StatusCode::kInvalidArgument);
  SamplingOptions o;
  o.samples_per_m2 = -1;
  EXPECT_EQ(SampleSurface(MakePlaneMesh(Eigen::Vector3f::Zero(), 1, 1, 1, 1), o).status().code(),
            StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------
// Mesh distance

TEST(MeshDistanceTest, IdenticalMeshesAreZero) {
  const Mesh s = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 4);
  auto r = ComputeMeshDistance(s, s, FastOptions());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_LT(r->chamfer_mm, 1e-3);
  EXPECT_LT(r->hausdorff_mm, 1e-3);
  EXPECT_EQ(r->completeness, 1.0);
  EXPECT_EQ(r->precision, 1.0);
  EXPECT_EQ(r->f_score, 1.0);
  EXPECT_EQ(r->num_recon_samples, 20000u);
  EXPECT_EQ(r->num_truth_samples, 20000u);
}

TEST(MeshDistanceTest, SphereOffsetByTwoMillimetres) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 5);
  const Mesh recon = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.502f, 5);
  auto r = ComputeMeshDistance(recon, truth, FastOptions());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->chamfer_mm, 2.0, 0.2);
  EXPECT_NEAR(r->accuracy_mm, 2.0, 0.2);
  EXPECT_NEAR(r->completeness_distance_mm, 2.0, 0.2);
  EXPECT_NEAR(r->hausdorff_mm, 2.0, 0.2);
  EXPECT_NEAR(r->hausdorff_percentile_mm, 2.0, 0.2);
  EXPECT_EQ(r->completeness, 1.0);
  EXPECT_EQ(r->precision, 1.0);

  // A different tessellation of the same offset sphere gives the same answer.
  const Mesh recon_uv = MakeUvSphereMesh(Eigen::Vector3f::Zero(), 0.502f, 200, 400);
  auto r_uv = ComputeMeshDistance(recon_uv, truth, FastOptions());
  ASSERT_TRUE(r_uv.ok());
  EXPECT_NEAR(r_uv->chamfer_mm, 2.0, 0.2);
  EXPECT_NEAR(r_uv->hausdorff_mm, 2.0, 0.3);

  // A threshold below the offset: nothing is matched.
  MeshDistanceOptions tight = FastOptions();
  tight.completeness_threshold_m = 0.001;
  auto r_tight = ComputeMeshDistance(recon, truth, tight);
  ASSERT_TRUE(r_tight.ok());
  EXPECT_EQ(r_tight->completeness, 0.0);
  EXPECT_EQ(r_tight->precision, 0.0);
  EXPECT_EQ(r_tight->f_score, 0.0);
}

TEST(MeshDistanceTest, MissingCapLowersCompleteness) {
  const float radius = 0.5f;
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), radius, 5);
  double removed = 0;
  const Mesh recon = WithoutCap(truth, 0.3f, &removed);  // cap of ~20% of the area
  ASSERT_NEAR(removed, 0.2, 0.01);
  auto r = ComputeMeshDistance(recon, truth, FastOptions());
  ASSERT_TRUE(r.ok());
  // Truth points of the cap within 1 cm of the cut rim still count as
  // complete: a band of ≈ rim length × 1 cm.
  const double band = 2 * kPi * 0.4 * 0.01 / (4 * kPi * radius * radius);
  EXPECT_NEAR(r->completeness, 1.0 - removed + band, 0.01);
  EXPECT_EQ(r->precision, 1.0);
  EXPECT_LT(r->accuracy_mm, 1e-3);
  // Farthest truth point: the pole, ~√(0.4² + 0.2²) m from the rim.
  EXPECT_NEAR(r->hausdorff_mm, 1000 * std::sqrt(0.4 * 0.4 + 0.2 * 0.2), 15);
  // The 95th percentile ignores the worst 5% of the missing 20%... but not all of it.
  EXPECT_LT(r->hausdorff_percentile_mm, r->hausdorff_mm);
  EXPECT_GT(r->hausdorff_percentile_mm, 100);
}

TEST(MeshDistanceTest, DeterministicAcrossRunsAndThreads) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 4);
  const Mesh recon = Scaled(MakeUvSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 40, 80), Eigen::Vector3f(1.01f, 1, 0.99f));
  MeshDistanceOptions o = FastOptions();
  o.num_threads = 1;
  auto a = ComputeMeshDistance(recon, truth, o);
  o.num_threads = 2;
  auto b = ComputeMeshDistance(recon, truth, o);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->chamfer_mm, b->chamfer_mm);
  EXPECT_EQ(a->hausdorff_mm, b->hausdorff_mm);
  EXPECT_EQ(a->hausdorff_percentile_mm, b->hausdorff_percentile_mm);
  EXPECT_EQ(a->completeness, b->completeness);
  o.include_vertices = true;
  auto c = ComputeMeshDistance(recon, truth, o);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->num_recon_samples, 20000u + recon.num_vertices());
  EXPECT_EQ(c->num_truth_samples, 20000u + truth.num_vertices());
}

TEST(MeshDistanceTest, ErrorsAreClear) {
  const Mesh s = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 2);
  auto empty_recon = ComputeMeshDistance(Mesh(), s);
  ASSERT_FALSE(empty_recon.ok());
  EXPECT_EQ(empty_recon.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(empty_recon.status().message().find("reconstruction"), std::string::npos)
      << empty_recon.status().message();
  auto empty_truth = ComputeMeshDistance(s, Mesh());
  ASSERT_FALSE(empty_truth.ok());
  EXPECT_NE(empty_truth.status().message().find("truth"), std::string::npos);
  MeshDistanceOptions bad;
  bad.completeness_threshold_m = 0;
  EXPECT_EQ(ComputeMeshDistance(s, s, bad).status().code(), StatusCode::kInvalidArgument);
  bad = MeshDistanceOptions();
  bad.hausdorff_percentile = 150;
  EXPECT_EQ(ComputeMeshDistance(s, s, bad).status().code(), StatusCode::kInvalidArgument);
  Mesh broken = s;
  broken.positions[0].x() = std::nanf("");
  EXPECT_EQ(ComputeMeshDistance(broken, s).status().code(), StatusCode::kDataLoss);
}

TEST(MeshDistanceTest, PercentileIsNearestRank) {
  std::vector<float> v;
  for (int i = 1; i <= 100; ++i) v.push_back(static_cast<float>(101 - i));
  EXPECT_EQ(Percentile(v, 95), 95.0);
  EXPECT_EQ(Percentile(v, 100), 100.0);
  EXPECT_EQ(Percentile(v, 0.5), 1.0);
  EXPECT_EQ(Percentile({}, 50), 0.0);
}

// ---------------------------------------------------------------------------
// Images

ImageRgb8 GradientImage(int w, int h) {
  ImageRgb8 img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      img.at(x, y, 0) = static_cast<uint8_t>(40 + (x * 3 + y) % 170);
      img.at(x, y, 1) = static_cast<uint8_t>(60 + (x * y) % 150);
      img.at(x, y, 2) = static_cast<uint8_t>(30 + (y * 5) % 200);
    }
  return img;
}

ImageRgb8 WithNoise(const ImageRgb8& img, double sigma, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, sigma);
  ImageRgb8 out = img;
  for (auto& v : out.storage()) v = static_cast<uint8_t>(std::clamp(v + std::lround(n(rng)), 0L, 255L));
  return out;
}

TEST(ImageMetricsTest, PsnrKnownValues) {
  const ImageRgb8 a = GradientImage(64, 48);
  auto same = ComputePsnr(a, a);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(*same, kPsnrCapDb);
  ImageRgb8 b = a;
  for (auto& v : b.storage()) v = static_cast<uint8_t>(v + 10);  // values stay below 255
  auto off = ComputePsnr(a, b);
  ASSERT_TRUE(off.ok());
  EXPECT_NEAR(*off, 20 * std::log10(255.0 / 10), 1e-9);

  // Only the left half differs; a mask on the right half sees identical pixels.
  ImageRgb8 c = a;
  ImageGray8 right(64, 48, 0), left(64, 48, 0);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      if (x < 32) {
        for (int ch = 0; ch < 3; ++ch) c.at(x, y, ch) = static_cast<uint8_t>(a.at(x, y, ch) + 10);
        left.at(x, y) = 255;
      } else {
        right.at(x, y) = 1;
      }
    }
  EXPECT_EQ(*ComputePsnr(a, c, &right), kPsnrCapDb);
  EXPECT_NEAR(*ComputePsnr(a, c, &left), 20 * std::log10(255.0 / 10), 1e-9);
  EXPECT_NEAR(*ComputePsnr(a, c), 10 * std::log10(255.0 * 255.0 / 50), 1e-9);

  ImageGray8 g1(10, 10, 100), g2(10, 10, 95);
  EXPECT_NEAR(*ComputePsnr(g1, g2), 20 * std::log10(255.0 / 5), 1e-9);
}

TEST(ImageMetricsTest, PsnrErrors) {
  const ImageRgb8 a = GradientImage(64, 48), b = GradientImage(48, 64);
  auto mismatch = ComputePsnr(a, b);
  ASSERT_FALSE(mismatch.ok());
  EXPECT_EQ(mismatch.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(mismatch.status().message().find("64x48"), std::string::npos) << mismatch.status().message();
  const ImageGray8 empty_mask(64, 48, 0), small_mask(8, 8, 255);
  EXPECT_EQ(ComputePsnr(a, a, &empty_mask).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputePsnr(a, a, &small_mask).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputePsnr(ImageRgb8(), ImageRgb8()).status().code(), StatusCode::kInvalidArgument);
}

TEST(ImageMetricsTest, SsimIdenticalNoisyAndConstant) {
  const ImageRgb8 a = GradientImage(80, 60);
  EXPECT_NEAR(*ComputeSsim(a, a), 1.0, 1e-12);
  SsimOptions per_channel;
  per_channel.channels = SsimChannels::kPerChannelMean;
  EXPECT_NEAR(*ComputeSsim(a, a, nullptr, per_channel), 1.0, 1e-12);
  double previous = 1.0;
  for (double sigma : {2.0, 8.0, 20.0, 50.0}) {
    const ImageRgb8 noisy = WithNoise(a, sigma, 1);
    const double s = *ComputeSsim(a, noisy);
    const double s_pc = *ComputeSsim(a, noisy, nullptr, per_channel);
    EXPECT_LT(s, previous) << "sigma " << sigma;
    EXPECT_LT(s_pc, 1.0);
    EXPECT_GT(s, 0.0);
    previous = s;
  }
  // Constant images 100 vs 110: only the luminance term differs,
  // (2·100·110 + C1) / (100² + 110² + C1).
  const ImageGray8 g1(20, 20, 100), g2(20, 20, 110);
  const double c1 = (0.01 * 255) * (0.01 * 255);
  EXPECT_NEAR(*ComputeSsim(g1, g2), (2 * 100 * 110 + c1) / (100 * 100 + 110 * 110 + c1), 1e-12);
}

TEST(ImageMetricsTest, SsimMaskAndErrors) {
  const ImageRgb8 a = GradientImage(80, 60);
  ImageRgb8 b = a;
  ImageGray8 clean(80, 60, 0);
  // Noise only in the left half; the mask covers the right part far from it.
  const ImageRgb8 noisy = WithNoise(a, 30, 2);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 80; ++x) {
      if (x < 40)
        for (int ch = 0; ch < 3; ++ch) b.at(x, y, ch) = noisy.at(x, y, ch);
      if (x >= 50) clean.at(x, y) = 255;
    }
  EXPECT_NEAR(*ComputeSsim(a, b, &clean), 1.0, 1e-12);
  EXPECT_LT(*ComputeSsim(a, b), 0.9);

  EXPECT_EQ(ComputeSsim(ImageGray8(10, 30), ImageGray8(10, 30)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeSsim(a, GradientImage(81, 60)).status().code(), StatusCode::kInvalidArgument);
  ImageGray8 border_only(80, 60, 0);
  for (int x = 0; x < 80; ++x) border_only.at(x, 0) = 255;  // no valid window is centred here
  EXPECT_EQ(ComputeSsim(a, a, &border_only).status().code(), StatusCode::kInvalidArgument);
}

TEST(ImageMetricsTest, DepthError) {
  ImageDepth16 truth(10, 10, 1000), est(10, 10, 1000);
  for (int x = 0; x < 10; ++x) {
    est.at(x, 0) = 1010;  // +10 mm on row 0
    est.at(x, 1) = 990;   // −10 mm on row 1
    est.at(x, 2) = 0;     // invalid estimate on row 2
    truth.at(x, 3) = 0;   // invalid truth on row 3
  }
  auto s = ComputeDepthError(est, truth);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->num_truth_valid, 90u);
  EXPECT_EQ(s->num_compared, 80u);
  EXPECT_NEAR(s->fraction_valid, 80.0 / 90.0, 1e-12);
  EXPECT_NEAR(s->mean_abs_error_mm, 200.0 / 80.0, 1e-12);
  EXPECT_NEAR(s->rmse_mm, std::sqrt(2000.0 / 80.0), 1e-12);
  EXPECT_NEAR(s->mean_signed_error_mm, 0.0, 1e-12);
  EXPECT_EQ(s->median_abs_error_mm, 0.0);

  ImageGray8 row0(10, 10, 0);
  for (int x = 0; x < 10; ++x) row0.at(x, 0) = 255;
  auto m = ComputeDepthError(est, truth, &row0);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->num_compared, 10u);
  EXPECT_EQ(m->mean_abs_error_mm, 10.0);
  EXPECT_EQ(m->mean_signed_error_mm, 10.0);
  EXPECT_EQ(m->fraction_valid, 1.0);

  EXPECT_EQ(ComputeDepthError(est, ImageDepth16(10, 10, 0)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeDepthError(est, ImageDepth16(9, 10, 5)).status().code(), StatusCode::kInvalidArgument);
  auto none = ComputeDepthError(ImageDepth16(10, 10, 0), truth);
  ASSERT_TRUE(none.ok());
  EXPECT_EQ(none->fraction_valid, 0.0);
  EXPECT_TRUE(std::isnan(none->mean_abs_error_mm));
}

TEST(ImageMetricsTest, MaskIouOfRectangles) {
  ImageGray8 p(20, 10, 0), t(20, 10, 0);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 10; ++x) {
      p.at(x, y) = 255;     // [0,10) × [0,10)
      t.at(x + 5, y) = 1;   // [5,15) × [0,10)
    }
  auto m = CompareMasks(p, t);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->intersection, 50u);
  EXPECT_EQ(m->union_count, 150u);
  EXPECT_NEAR(m->iou, 1.0 / 3, 1e-12);
  EXPECT_NEAR(m->precision, 0.5, 1e-12);
  EXPECT_NEAR(m->recall, 0.5, 1e-12);
  EXPECT_EQ(CompareMasks(p, p)->iou, 1.0);

  const ImageGray8 empty(20, 10, 0);
  EXPECT_EQ(CompareMasks(empty, empty)->iou, 1.0);
  EXPECT_EQ(CompareMasks(empty, empty)->precision, 1.0);
  EXPECT_EQ(CompareMasks(empty, t)->iou, 0.0);
  EXPECT_EQ(CompareMasks(empty, t)->precision, 0.0);
  EXPECT_EQ(CompareMasks(empty, t)->recall, 0.0);
  EXPECT_EQ(CompareMasks(p, ImageGray8(10, 20)).status().code(), StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------
// Flicker

FlickerOptions FastFlicker() {
  FlickerOptions o;
  o.sampling.num_samples = 5000;
  return o;
}

TEST(FlickerTest, StaticReconstructionHasZeroFlicker) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 4);
  const Mesh recon = MakeUvSphereMesh(Eigen::Vector3f::Zero(), 0.501f, 50, 100);
  FlickerAccumulator acc(FastFlicker());
  for (int t = 0; t < 4; ++t) ASSERT_TRUE(acc.Add(recon, truth).ok());
  EXPECT_EQ(acc.num_frames(), 4u);
  EXPECT_EQ(acc.pairs().size(), 3u);
  EXPECT_EQ(acc.Mean(), 0.0);
  EXPECT_EQ(acc.num_samples(), 5000u);
  EXPECT_EQ(acc.total_samples_used(), 3u * 5000u);
}

TEST(FlickerTest, ReconstructionMovingWithTheTruthHasNoFlicker) {
  // An ellipsoid, so that the rotation is visible; the reconstruction is a
  // different tessellation, slightly larger, moving rigidly with the truth.
  const Eigen::Vector3f axes(0.3f, 0.2f, 0.5f);
  const Mesh truth0 = Scaled(MakeSphereMesh(Eigen::Vector3f::Zero(), 1.0f, 4), axes);
  const Mesh recon0 = Scaled(MakeUvSphereMesh(Eigen::Vector3f::Zero(), 1.003f, 60, 120), axes);
  FlickerAccumulator acc(FastFlicker());
  for (int t = 0; t < 5; ++t) {
    Eigen::Affine3f motion = Eigen::Affine3f::Identity();
    motion.translate(Eigen::Vector3f(0.05f * t, -0.02f * t, 0.01f * t));
    motion.rotate(Eigen::AngleAxisf(0.2f * t, Eigen::Vector3f(1, 2, 3).normalized()));
    ASSERT_TRUE(acc.Add(Transformed(recon0, motion), Transformed(truth0, motion)).ok());
  }
  EXPECT_LT(acc.Mean(), 0.01);
  EXPECT_GT(acc.total_samples_used(), 4u * 4900u);

  // The same reconstruction left behind while the truth moves flickers.
  FlickerAccumulator left_behind(FastFlicker());
  for (int t = 0; t < 3; ++t) {
    Eigen::Affine3f motion = Eigen::Affine3f::Identity();
    motion.translate(Eigen::Vector3f(0.004f * t, 0, 0));
    ASSERT_TRUE(left_behind.Add(recon0, Transformed(truth0, motion)).ok());
  }
  EXPECT_GT(left_behind.Mean(), 1.0);
}

TEST(FlickerTest, AlternatingOffsetOfOneMillimetre) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 5);
  const Mesh outer = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.501f, 5);
  const Mesh inner = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.499f, 5);
  FlickerAccumulator acc(FastFlicker());
  for (int t = 0; t < 6; ++t) ASSERT_TRUE(acc.Add(t % 2 == 0 ? outer : inner, truth).ok());
  EXPECT_NEAR(acc.Mean(), 2.0, 0.05);
  for (const auto& p : acc.pairs()) {
    EXPECT_NEAR(p.flicker_mm, 2.0, 0.05);
    EXPECT_EQ(p.num_samples_used, 5000u);
  }
  auto pair = ComputeFlicker(outer, truth, inner, truth, FastFlicker());
  ASSERT_TRUE(pair.ok());
  EXPECT_NEAR(pair->flicker_mm, acc.pairs()[0].flicker_mm, 1e-9);

  // Signed offsets: outward is positive.
  auto samples = SampleSurface(truth, FastFlicker().sampling);
  ASSERT_TRUE(samples.ok());
  auto d_out = ComputeNormalOffsets(outer, truth, *samples);
  ASSERT_TRUE(d_out.ok());
  for (float d : *d_out) ASSERT_NEAR(d, 0.001f, 1e-4f);
}

// Independent per-frame noise: a plane made of separate 2 cm tiles, each
// displaced along the normal by its own N(0, σ²) every frame. Then
// d_{t+1} − d_t ~ N(0, 2σ²) and E|d_{t+1} − d_t| = 2σ/√π. (Samples within
// ~σ of a tile edge may snap to the neighbouring tile, which biases the
// result low by a few % at σ = tile / 80; see docs/metrics.md.)
TEST(FlickerTest, IndependentNoiseGivesTwoSigmaOverRootPi) {
  const int tiles = 50;
  const float size = 1.0f, tile = size / tiles, sigma = 0.00025f;
  const Mesh truth = MakePlaneMesh(Eigen::Vector3f::Zero(), size, size, tiles, tiles);
  std::mt19937 rng(17);
  std::normal_distribution<float> noise(0, sigma);
  FlickerAccumulator acc(FastFlicker());
  for (int t = 0; t < 8; ++t) {
    Mesh recon;
    for (int j = 0; j < tiles; ++j)
      for (int i = 0; i < tiles; ++i) {
        const uint32_t base = static_cast<uint32_t>(recon.positions.size());
        const float x = -0.5f * size + i * tile, y = -0.5f * size + j * tile, z = noise(rng);
        recon.positions.insert(recon.positions.end(),
                               {{x, y, z}, {x + tile, y, z}, {x + tile, y + tile, z}, {x, y + tile, z}});
        recon.triangles.push_back({base, base + 1, base + 2});
        recon.triangles.push_back({base, base + 2, base + 3});
      }
    ASSERT_TRUE(acc.Add(recon, truth).ok());
  }
  const double expected_mm = 1000 * 2 * sigma / std::sqrt(kPi);
  EXPECT_NEAR(acc.Mean(), expected_mm, 0.06 * expected_mm);
}

TEST(FlickerTest, HolesAndEmptyFramesAreSkipped) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 4);
  double removed = 0;
  const Mesh holey = WithoutCap(truth, 0.3f, &removed);
  FlickerAccumulator acc(FastFlicker());
  ASSERT_TRUE(acc.Add(holey, truth).ok());
  ASSERT_TRUE(acc.Add(holey, truth).ok());
  ASSERT_TRUE(acc.Add(Mesh(), truth).ok());  // a failed frame
  ASSERT_EQ(acc.pairs().size(), 2u);
  // Samples of the cap farther than the 2 cm cutoff from the rim are not
  // used (the rest of the cap lies in a band of ≈ rim length × 2 cm).
  const double used = static_cast<double>(acc.pairs()[0].num_samples_used) / 5000;
  EXPECT_GT(used, 1.0 - removed);
  EXPECT_LT(used, 1.0 - removed + 0.03);
  EXPECT_EQ(acc.pairs()[0].flicker_mm, 0.0);
  EXPECT_EQ(acc.pairs()[1].num_samples_used, 0u);
  EXPECT_TRUE(std::isnan(acc.pairs()[1].flicker_mm));
  EXPECT_EQ(acc.num_pairs_used(), 1u);
  EXPECT_EQ(acc.Mean(), 0.0);

  FlickerAccumulator none(FastFlicker());
  EXPECT_TRUE(std::isnan(none.Mean()));
}

TEST(FlickerTest, Errors) {
  const Mesh truth = MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 3);
  FlickerAccumulator acc(FastFlicker());
  EXPECT_EQ(acc.Add(truth, Mesh()).code(), StatusCode::kInvalidArgument);  // empty first truth
  ASSERT_TRUE(acc.Add(truth, truth).ok());
  const Status changed = acc.Add(truth, MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 2));
  EXPECT_EQ(changed.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(changed.message().find("topology"), std::string::npos) << changed.message();
  EXPECT_EQ(acc.num_frames(), 1u);
  FlickerOptions bad = FastFlicker();
  bad.cutoff_m = -1;
  EXPECT_EQ(ComputeFlicker(truth, truth, truth, truth, bad).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeFlicker(truth, truth, truth, MakeSphereMesh(Eigen::Vector3f::Zero(), 0.5f, 2)).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace holo::metrics
