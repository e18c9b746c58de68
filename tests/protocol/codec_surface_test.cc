// G3 (protocol/surface_codec.h): the surface coded as the distance samples
// marching cubes reads.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <random>
#include <utility>

#include "protocol/geometry_codec.h"
#include "protocol/surface_codec.h"

namespace holo::protocol {
namespace {

constexpr float kVoxel = 0.016f;
constexpr float kTrunc = 0.032f;

struct Ball {
  Eigen::Vector3f centre;
  float radius;
};

// A truncated distance field of the union of `balls` on a 16 mm grid, with
// a little noise; samples deeper inside than `observed_depth` are unobserved
// (as behind a fused surface).
SdfGrid BallsGrid(const std::vector<Ball>& balls, float noise_m = 0.0005f, float observed_depth = 0.05f,
                  int n = 48) {
  SdfGrid g;
  g.origin = Eigen::Vector3f(-0.37f, -0.41f, -0.39f);
  g.voxel_m = kVoxel;
  g.nx = n;
  g.ny = n + 3;
  g.nz = n - 2;
  g.sdf.resize(g.size());
  std::mt19937 rng(7);
  std::normal_distribution<float> gauss(0.0f, noise_m);
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        const Eigen::Vector3f p = g.origin + kVoxel * Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
        float d = 1e9f;
        for (const Ball& b : balls) d = std::min(d, (p - b.centre).norm() - b.radius);
        float& v = g.sdf[g.Index(x, y, z)];
        if (d < -observed_depth) {
          v = std::nanf("");
        } else {
          v = std::clamp(d + (noise_m > 0 ? gauss(rng) : 0.0f), -kTrunc, kTrunc);
        }
      }
  return g;
}

double DistanceToBalls(const Eigen::Vector3f& p, const std::vector<Ball>& balls) {
  double d = 1e9;
  for (const Ball& b : balls) d = std::min(d, static_cast<double>((p - b.centre).norm() - b.radius));
  return d;
}

// Every undirected edge is shared by exactly two triangles, once in each
// direction (closed and consistently oriented).
void ExpectClosedAndOriented(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  size_t bad = 0;
  for (const auto& [e, c] : directed) {
    if (c != 1) ++bad;
    auto it = directed.find({e.second, e.first});
    if (it == directed.end() || it->second != 1) ++bad;
  }
  EXPECT_EQ(bad, 0u);
}

TEST(SurfaceCodec, SphereRoundTripIsExactAndOnTheSurface) {
  const std::vector<Ball> balls = {{Eigen::Vector3f(0.01f, 0.02f, -0.03f), 0.25f}};
  const SdfGrid g = BallsGrid(balls, 0.0f);
  std::vector<uint8_t> blob;
  Mesh enc_mesh;
  SurfaceEncodeStats st;
  SurfaceEncodeOptions o;
  o.position_step_m = 0.001f;
  ASSERT_TRUE(EncodeSurface(g, o, &blob, &enc_mesh, &st).ok());
  EXPECT_EQ(*PeekGeometryCodec(blob), GeometryCodec::kG3);
  Mesh out;
  const Status s = DecodeGeometry(blob, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(out.Validate().ok());
  ASSERT_GT(out.num_triangles(), 2000u);
  // The decoder makes the mesh the encoder said it would, exactly.
  ASSERT_EQ(out.positions, enc_mesh.positions);
  ASSERT_EQ(out.triangles, enc_mesh.triangles);
  EXPECT_EQ(st.vertices, out.num_vertices());
  EXPECT_EQ(st.dropped_cubes, 0u);
  // On the sphere: within the quantization (0.5 mm along the normal where
  // the labels' normal estimate is right) and marching cubes' interpolation
  // of a curved field (~0.1 mm at 16 mm, r = 25 cm) on average; at worst
  // where the estimate takes an edge for more grazing than it is.
  double worst = 0, sum2 = 0;
  for (const auto& p : out.positions) {
    const double d = DistanceToBalls(p, balls);
    worst = std::max(worst, std::abs(d));
    sum2 += d * d;
  }
  EXPECT_LT(std::sqrt(sum2 / static_cast<double>(out.num_vertices())), 0.0005);
  EXPECT_LT(worst, 0.0025);
  ExpectClosedAndOriented(out);
  // Normals point out of the ball.
  size_t outward = 0;
  for (size_t i = 0; i < out.num_vertices(); ++i) outward += out.normals[i].dot(out.positions[i] - balls[0].centre) > 0;
  EXPECT_EQ(outward, out.num_vertices());
}

TEST(SurfaceCodec, CoarserStepCostsLessAndStaysNearTheSurface) {
  const std::vector<Ball> balls = {{Eigen::Vector3f(0.0f, 0.01f, 0.02f), 0.22f}};
  const SdfGrid g = BallsGrid(balls, 0.0f);
  size_t last = SIZE_MAX;
  for (float step : {0.0005f, 0.001f, 0.002f, 0.004f}) {
    SurfaceEncodeOptions o;
    o.position_step_m = step;
    std::vector<uint8_t> blob;
    ASSERT_TRUE(EncodeSurface(g, o, &blob).ok());
    Mesh out;
    ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
    double sum2 = 0;
    for (const auto& p : out.positions) sum2 += std::pow(DistanceToBalls(p, balls), 2);
    // Half a step along the normal at most, a third of it on average (RMS
    // of a uniform error is step/√12), plus the estimate's misses.
    EXPECT_LT(std::sqrt(sum2 / static_cast<double>(out.num_vertices())), step / 2.5 + 0.0003) << "step " << step;
    EXPECT_LT(blob.size(), last) << "step " << step;
    last = blob.size();
  }
}

TEST(SurfaceCodec, SmallFragmentsAreDroppedUnlessAsked) {
  const std::vector<Ball> body = {{Eigen::Vector3f(-0.05f, 0.0f, 0.0f), 0.2f}};
  std::vector<Ball> with_speck = body;
  with_speck.push_back({Eigen::Vector3f(0.28f, 0.28f, 0.2f), 0.012f});
  const SdfGrid g = BallsGrid(with_speck);
  std::vector<uint8_t> blob;
  SurfaceEncodeStats st;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob, nullptr, &st).ok());
  EXPECT_GT(st.dropped_cubes, 0u);
  Mesh out;
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  for (const auto& p : out.positions) ASSERT_LT((p - with_speck[1].centre).norm(), 10.0f) << "nothing";
  for (const auto& p : out.positions) EXPECT_GT((p - with_speck[1].centre).norm(), 0.04f);
  SurfaceEncodeOptions keep;
  keep.min_component_triangles = 0;
  blob.clear();
  ASSERT_TRUE(EncodeSurface(g, keep, &blob, nullptr, &st).ok());
  EXPECT_EQ(st.dropped_cubes, 0u);
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  size_t near_speck = 0;
  for (const auto& p : out.positions) near_speck += (p - with_speck[1].centre).norm() < 0.04f;
  EXPECT_GT(near_speck, 0u);
}

TEST(SurfaceCodec, UnobservedCornersMakeNoSurface) {
  const std::vector<Ball> balls = {{Eigen::Vector3f(0.0f, 0.0f, 0.0f), 0.25f}};
  SdfGrid g = BallsGrid(balls);
  // The pods never saw the half with z > 0.
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x)
        if (g.origin.z() + kVoxel * static_cast<float>(z) > 0) g.sdf[g.Index(x, y, z)] = std::nanf("");
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob).ok());
  Mesh out;
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  ASSERT_GT(out.num_triangles(), 500u);
  for (const auto& p : out.positions) EXPECT_LE(p.z(), 0.0f + 1e-6f);
}

TEST(SurfaceCodec, EmptyAndTinyGridsRoundTrip) {
  SdfGrid g;
  g.voxel_m = kVoxel;
  g.nx = g.ny = g.nz = 1;
  g.sdf = {0.01f};
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob).ok());
  Mesh out;
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  EXPECT_EQ(out.num_triangles(), 0u);
  // One cube with one corner inside: one triangle, its corners on the three
  // edges from that corner, a quarter of the way along (−4 mm vs +12 mm).
  g.nx = g.ny = g.nz = 2;
  g.sdf.assign(8, 0.012f);
  g.sdf[0] = -0.004f;
  SurfaceEncodeOptions keep;
  keep.min_component_triangles = 0;
  blob.clear();
  ASSERT_TRUE(EncodeSurface(g, keep, &blob).ok());
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  ASSERT_EQ(out.num_triangles(), 1u);
  for (const auto& p : out.positions) {
    EXPECT_EQ((p.array() != 0).count(), 1);
    EXPECT_NEAR(p.norm(), 0.25f * kVoxel, 0.25f * kVoxel);
  }
}

TEST(SurfaceCodec, BadGridsAreRefusedWithAReason) {
  SdfGrid g = BallsGrid({{Eigen::Vector3f::Zero(), 0.2f}});
  std::vector<uint8_t> blob;
  SdfGrid bad = g;
  bad.sdf.pop_back();
  Status s = EncodeSurface(bad, {}, &blob);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("values"), std::string::npos) << s.ToString();
  bad = g;
  bad.voxel_m = 0;
  EXPECT_EQ(EncodeSurface(bad, {}, &blob).code(), StatusCode::kInvalidArgument);
  bad = g;
  bad.origin.x() = std::nanf("");
  EXPECT_EQ(EncodeSurface(bad, {}, &blob).code(), StatusCode::kInvalidArgument);
  bad = g;
  bad.nx = 0;
  EXPECT_EQ(EncodeSurface(bad, {}, &blob).code(), StatusCode::kInvalidArgument);
  SurfaceEncodeOptions o;
  o.position_step_m = 0.01f;  // over half the voxel
  EXPECT_EQ(EncodeSurface(g, o, &blob).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(blob.empty());
  // EncodeGeometry codes meshes only.
  GeometryEncodeOptions go;
  go.codec = GeometryCodec::kG3;
  EXPECT_EQ(EncodeGeometry(Mesh{}, go, &blob).code(), StatusCode::kInvalidArgument);
}

// A grid over the format's limit, unobserved except near `balls` (each
// entry: a ball and the half-size of the observed cube around it).
SdfGrid SparseBigGrid(const std::vector<std::pair<Ball, float>>& balls, int n) {
  SdfGrid g;
  g.origin = Eigen::Vector3f(-0.5f, -0.5f, -0.5f);
  g.voxel_m = kVoxel;
  g.nx = g.ny = g.nz = n;
  g.sdf.assign(g.size(), std::nanf(""));
  for (const auto& [b, half] : balls) {
    const Eigen::Vector3f lo = (b.centre - Eigen::Vector3f::Constant(half) - g.origin) / kVoxel;
    const Eigen::Vector3f hi = (b.centre + Eigen::Vector3f::Constant(half) - g.origin) / kVoxel;
    for (int z = std::max(0, static_cast<int>(lo.z())); z <= std::min(n - 1, static_cast<int>(hi.z())); ++z)
      for (int y = std::max(0, static_cast<int>(lo.y())); y <= std::min(n - 1, static_cast<int>(hi.y())); ++y)
        for (int x = std::max(0, static_cast<int>(lo.x())); x <= std::min(n - 1, static_cast<int>(hi.x())); ++x) {
          const Eigen::Vector3f p =
              g.origin + kVoxel * Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
          const float d = std::clamp((p - b.centre).norm() - b.radius, -kTrunc, kTrunc);
          float& v = g.sdf[g.Index(x, y, z)];
          v = std::isnan(v) ? d : std::min(v, d);
        }
  }
  return g;
}

TEST(SurfaceCodec, AGridOverTheLimitIsCutToTheSurfaceItKeeps) {
  // 262³ samples (padded 266³ > 2^24): a body near one corner and, 3.5 m
  // away, a speck too small to keep (as a fused volume's far floater
  // stretches the site's box).
  const int n = 262;
  ASSERT_GT(SurfacePaddedSamples(n, n, n), kSurfaceMaxSamples);
  const Ball body{Eigen::Vector3f(0.0f, 0.05f, -0.02f), 0.3f};
  const Ball speck{Eigen::Vector3f(3.5f, 3.5f, 3.4f), 0.012f};
  {  // one big grid alive at a time
    const SdfGrid g = SparseBigGrid({{body, 0.4f}, {speck, 0.05f}}, n);
    std::vector<uint8_t> blob;
    Mesh enc;
    SurfaceEncodeStats st;
    const Status s = EncodeSurface(g, {}, &blob, &enc, &st);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_LT(st.grid_samples, g.size() / 100) << "coded on the cut";
    Mesh out;
    ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
    ASSERT_EQ(out.triangles, enc.triangles);
    ASSERT_GT(out.num_triangles(), 2000u);
    // The same surface as the body's grid alone gives, nothing of the speck.
    const SdfGrid alone = SparseBigGrid({{body, 0.4f}}, 80);
    std::vector<uint8_t> blob_alone;
    Mesh enc_alone;
    ASSERT_TRUE(EncodeSurface(alone, {}, &blob_alone, &enc_alone).ok());
    ASSERT_EQ(out.num_vertices(), enc_alone.num_vertices());
    ASSERT_EQ(out.triangles, enc_alone.triangles);
    for (size_t i = 0; i < out.num_vertices(); ++i)
      ASSERT_LT((out.positions[i] - enc_alone.positions[i]).norm(), 1e-5f) << i;
    for (const auto& p : out.positions) EXPECT_LT(DistanceToBalls(p, {body}), 0.002);
  }
  // Two kept bodies at opposite corners still do not fit: refused, naming the span.
  const SdfGrid two = SparseBigGrid(
      {{Ball{Eigen::Vector3f::Constant(-0.15f), 0.3f}, 0.4f}, {Ball{Eigen::Vector3f::Constant(3.35f), 0.3f}, 0.4f}}, n);
  std::vector<uint8_t> blob;
  const Status t = EncodeSurface(two, {}, &blob);
  EXPECT_EQ(t.code(), StatusCode::kOutOfRange);
  EXPECT_NE(t.message().find("surface spans"), std::string::npos) << t.ToString();
  EXPECT_TRUE(blob.empty());
}

TEST(SurfaceCodec, EncodingIsDeterministic) {
  const SdfGrid g = BallsGrid({{Eigen::Vector3f(0.02f, 0.0f, 0.0f), 0.2f}});
  std::vector<uint8_t> a, b;
  ASSERT_TRUE(EncodeSurface(g, {}, &a).ok());
  ASSERT_TRUE(EncodeSurface(g, {}, &b).ok());
  EXPECT_EQ(a, b);
}

// A fixed grid for the G3 bitstream test: two balls, an odd width (SIMD
// tails), hash noise, unobserved samples (NaN) deep inside and at random,
// and exact -0.0 samples.
SdfGrid FrozenGrid() {
  SdfGrid g;
  g.origin = Eigen::Vector3f(-0.41f, -0.33f, -0.29f);
  g.voxel_m = 0.016f;
  g.nx = 45;
  g.ny = 38;
  g.nz = 35;
  g.sdf.resize(g.size());
  auto hash = [](uint32_t v) {
    v ^= v >> 16;
    v *= 0x7feb352du;
    v ^= v >> 15;
    v *= 0x846ca68bu;
    v ^= v >> 16;
    return v;
  };
  const Eigen::Vector3f c0(-0.05f, 0.0f, 0.0f), c1(0.17f, 0.05f, -0.02f);
  for (int z = 0; z < g.nz; ++z)
    for (int y = 0; y < g.ny; ++y)
      for (int x = 0; x < g.nx; ++x) {
        const uint32_t i = static_cast<uint32_t>(g.Index(x, y, z));
        const Eigen::Vector3f p = g.origin + g.voxel_m * Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
        const float d = std::min((p - c0).norm() - 0.2f, (p - c1).norm() - 0.11f);
        const float noise = (static_cast<float>(hash(i) % 2001u) - 1000.0f) * 1e-6f;  // ±1 mm
        float v = std::clamp(d + noise, -0.032f, 0.032f);
        if (d < -0.05f || hash(i ^ 0x9e3779b9u) % 97u == 0) v = std::nanf("");
        if (hash(i + 17u) % 89u == 0) v = -0.0f;
        g.sdf[i] = v;
      }
  return g;
}

uint64_t Fnv1a(uint64_t h, const void* data, size_t n) {
  const auto* b = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  return h;
}

// The encoder's output and the decoder's mesh are frozen: a speed-up must
// leave both bit for bit as they were (the hashes were made by the code
// before the 2026-12-06 speed-up and checked against it, with GCC at -O3
// and clang at -O1). A deliberate change of the format or of the encoder's
// choices updates them and says so in PROTOCOL.md / docs/codecs.md.
TEST(SurfaceCodec, TheBitstreamAndTheDecodedMeshAreFrozen) {
  const SdfGrid g = FrozenGrid();
  std::vector<uint8_t> blob;
  Mesh from_encoder, decoded;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob, &from_encoder).ok());
  ASSERT_TRUE(DecodeGeometry(blob, &decoded).ok());
  EXPECT_EQ(blob.size(), 2691u);
  EXPECT_EQ(decoded.num_vertices(), 3457u);
  EXPECT_EQ(decoded.num_triangles(), 6425u);
  uint64_t hb = 1469598103934665603ull, hm = 1469598103934665603ull;
  hb = Fnv1a(hb, blob.data(), blob.size());
  for (const Eigen::Vector3f& p : decoded.positions) hm = Fnv1a(hm, p.data(), 3 * sizeof(float));
  for (const auto& t : decoded.triangles) hm = Fnv1a(hm, t.data(), 3 * sizeof(uint32_t));
  EXPECT_EQ(hb, 0x10c8f4fb98de0939ull);
  EXPECT_EQ(hm, 0x41e1b80a1c72baebull);
  EXPECT_EQ(from_encoder.positions, decoded.positions);
  EXPECT_EQ(from_encoder.triangles, decoded.triangles);
}

// The site's grids hold finite distances or NaN; a caller's infinite
// samples count as observed and far (their crossings on the edge's end), never
// as undefined behaviour.
TEST(SurfaceCodec, InfiniteSamplesEncodeToAValidSurface) {
  SdfGrid g = FrozenGrid();
  size_t changed = 0;
  for (size_t i = 0; i < g.sdf.size(); i += 7) {
    if (g.sdf[i] == g.sdf[i]) {
      g.sdf[i] = g.sdf[i] < 0 ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
      ++changed;
    }
  }
  ASSERT_GT(changed, 1000u);
  std::vector<uint8_t> blob;
  Mesh from_encoder, decoded;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob, &from_encoder).ok());
  ASSERT_TRUE(DecodeGeometry(blob, &decoded).ok());
  EXPECT_GT(decoded.num_triangles(), 1000u);
  EXPECT_TRUE(decoded.Validate().ok());
  EXPECT_EQ(from_encoder.positions, decoded.positions);
}

TEST(SurfaceCodec, EveryPrefixIsRefused) {
  const SdfGrid g = BallsGrid({{Eigen::Vector3f(0.0f, 0.0f, 0.0f), 0.12f}}, 0.0005f, 0.05f, 24);
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob).ok());
  Mesh out;
  for (size_t n = 0; n < blob.size(); ++n) {
    const Status s = DecodeGeometry(std::span<const uint8_t>(blob.data(), n), &out);
    ASSERT_EQ(s.code(), StatusCode::kDataLoss) << "prefix of " << n << " bytes";
    ASSERT_TRUE(out.empty());
  }
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
}

TEST(SurfaceCodec, BitFlipsAreRefusedOrDecodeToAValidMesh) {
  const SdfGrid g = BallsGrid({{Eigen::Vector3f(0.0f, 0.0f, 0.0f), 0.12f}}, 0.0005f, 0.05f, 24);
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob).ok());
  std::mt19937 rng(3);
  Mesh out;
  int refused = 0;
  for (int i = 0; i < 3000; ++i) {
    std::vector<uint8_t> b = blob;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int k = 0; k < flips; ++k) b[rng() % b.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
    const Status s = DecodeGeometry(b, &out);
    if (!s.ok()) {
      ASSERT_EQ(s.code(), StatusCode::kDataLoss) << s.ToString();
      ASSERT_TRUE(out.empty());
      ++refused;
    } else {
      ASSERT_TRUE(out.Validate().ok());
    }
  }
  EXPECT_GT(refused, 2000);
}

TEST(SurfaceCodec, HeaderFieldsAreChecked) {
  const SdfGrid g = BallsGrid({{Eigen::Vector3f(0.0f, 0.0f, 0.0f), 0.12f}}, 0.0005f, 0.05f, 24);
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeSurface(g, {}, &blob).ok());
  Mesh out;
  auto expect_refused = [&](std::vector<uint8_t> b, const char* what) {
    const Status s = DecodeGeometry(b, &out);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << what;
    EXPECT_NE(s.message().find(what), std::string::npos) << s.ToString();
  };
  std::vector<uint8_t> b = blob;
  b[1] = 1;  // flags
  expect_refused(b, "flags");
  b = blob;
  b[4] ^= 1;  // vertex count off by one
  expect_refused(b, "vertices");
  b = blob;
  const float big = 4.0f;  // voxel
  std::memcpy(&b[12 + 12], &big, 4);
  expect_refused(b, "g3.voxel");
  b = blob;
  // Axes: origin (12 bytes), voxel (4), levels (1), then nx−1, ny−1, nz−1.
  auto set_axes = [&](uint16_t nx1, uint16_t ny1, uint16_t nz1) {
    std::vector<uint8_t> c = blob;
    std::memcpy(&c[12 + 17], &nx1, 2);
    std::memcpy(&c[12 + 19], &ny1, 2);
    std::memcpy(&c[12 + 21], &nz1, 2);
    return c;
  };
  expect_refused(set_axes(0xFFFF, 23, 23), "exceeds 4096");
  // A thin grid of few samples per brick row still needs its margin: too large.
  expect_refused(set_axes(4095, 4095, 0), "too large");
  // More bricks than the brick stream can hold symbols for.
  expect_refused(set_axes(999, 999, 1), "bricks cannot fit");
}

}  // namespace
}  // namespace holo::protocol
