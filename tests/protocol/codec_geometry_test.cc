#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include "protocol/geometry_codec.h"
#include "protocol/test_meshes.h"

namespace holo::protocol {
namespace {

struct Errors {
  double max_mm = 0, rms_mm = 0, max_normal_deg = 0;
  int color_max = 0;
};

Errors Compare(const Mesh& in, const Mesh& out, const std::vector<uint32_t>& map) {
  Errors e;
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < in.num_vertices(); ++i) {
    if (map[i] == UINT32_MAX) continue;
    const double d = (in.positions[i] - out.positions[map[i]]).norm() * 1000.0;
    e.max_mm = std::max(e.max_mm, d);
    sum += d * d;
    ++n;
    if (!in.normals.empty() && !out.normals.empty()) {
      const float c = std::clamp(in.normals[i].normalized().dot(out.normals[map[i]].normalized()), -1.0f, 1.0f);
      e.max_normal_deg = std::max(e.max_normal_deg, std::acos(c) * 180.0 / M_PI);
    }
    if (!in.colors.empty() && !out.colors.empty())
      for (int c = 0; c < 3; ++c) e.color_max = std::max(e.color_max, std::abs(in.colors[i][c] - out.colors[map[i]][c]));
  }
  e.rms_mm = n ? std::sqrt(sum / n) : 0;
  return e;
}

// Triangles of `a` mapped through `map` equal those of `b` as sets of rotated triangles.
void ExpectSameConnectivity(const Mesh& a, const Mesh& b, const std::vector<uint32_t>& map) {
  auto canon = [](std::array<uint32_t, 3> t) {
    while (!(t[0] <= t[1] && t[0] <= t[2])) t = {t[1], t[2], t[0]};
    return t;
  };
  std::vector<std::array<uint32_t, 3>> ta, tb;
  for (const auto& t : a.triangles) ta.push_back(canon({map[t[0]], map[t[1]], map[t[2]]}));
  for (const auto& t : b.triangles) tb.push_back(canon(t));
  std::sort(ta.begin(), ta.end());
  std::sort(tb.begin(), tb.end());
  EXPECT_EQ(ta, tb);
}

TEST(GeometryCodec, G0RoundTripHalfPrecision) {
  const Mesh in = test::NoisySphere(40, 60);
  GeometryEncodeOptions o;
  o.codec = GeometryCodec::kG0;
  std::vector<uint8_t> blob;
  std::vector<uint32_t> map;
  ASSERT_TRUE(EncodeGeometry(in, o, &blob, &map).ok());
  EXPECT_EQ(*PeekGeometryCodec(blob), GeometryCodec::kG0);
  Mesh out;
  const Status s = DecodeGeometry(blob, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(CheckMesh(out).ok());
  EXPECT_EQ(out.num_triangles(), in.num_triangles());
  const Errors e = Compare(in, out, map);
  EXPECT_LT(e.max_mm, 1.0);  // fp16 below 2 m: spacing ≤ 0.98 mm
  EXPECT_LT(e.max_normal_deg, 0.2);
  EXPECT_EQ(e.color_max, 0);
  ExpectSameConnectivity(in, out, map);
}

TEST(GeometryCodec, G0WeldsDuplicateVertices) {
  Mesh in;
  in.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  in.triangles = {{0, 1, 2}, {3, 5, 4}};
  GeometryEncodeOptions o;
  o.codec = GeometryCodec::kG0;
  std::vector<uint8_t> blob;
  std::vector<uint32_t> map;
  ASSERT_TRUE(EncodeGeometry(in, o, &blob, &map).ok());
  Mesh out;
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  EXPECT_EQ(out.num_vertices(), 4u);
  EXPECT_EQ(map[1], map[3]);
  EXPECT_EQ(map[2], map[4]);
}

TEST(GeometryCodec, G1RoundTripWithinStep) {
  const Mesh in = test::NoisySphere(60, 90);
  for (float step : {0.001f, 0.0005f, 0.004f}) {
    GeometryEncodeOptions o;
    o.position_step_m = step;
    std::vector<uint8_t> blob;
    std::vector<uint32_t> map;
    ASSERT_TRUE(EncodeGeometry(in, o, &blob, &map).ok());
    Mesh out;
    const Status s = DecodeGeometry(blob, &out);
    ASSERT_TRUE(s.ok()) << s.ToString();
    ASSERT_TRUE(CheckMesh(out).ok());
    ASSERT_EQ(out.num_vertices(), in.num_vertices());
    const Errors e = Compare(in, out, map);
    EXPECT_LE(e.max_mm, step * 1000 * std::sqrt(3.0f) / 2 + 1e-3) << "step " << step;
    EXPECT_LT(e.max_normal_deg, 1.5);
    EXPECT_EQ(e.color_max, 0);
    ExpectSameConnectivity(in, out, map);
  }
}

TEST(GeometryCodec, G1IsMuchSmallerThanG0) {
  const Mesh in = test::NoisySphere(150, 200);
  std::vector<uint8_t> g0, g1;
  GeometryEncodeOptions o;
  o.codec = GeometryCodec::kG0;
  ASSERT_TRUE(EncodeGeometry(in, o, &g0).ok());
  o.codec = GeometryCodec::kG1;
  ASSERT_TRUE(EncodeGeometry(in, o, &g1).ok());
  EXPECT_LT(g1.size() * 4, g0.size()) << "G0 " << g0.size() << " G1 " << g1.size();
}

TEST(GeometryCodec, WithoutNormalsOrColorsAndOptions) {
  Mesh in = test::NoisySphere(20, 30);
  in.normals.clear();
  in.colors.clear();
  for (auto codec : {GeometryCodec::kG0, GeometryCodec::kG1}) {
    for (bool opt : {true, false}) {
      GeometryEncodeOptions o;
      o.codec = codec;
      o.optimize_order = opt;
      std::vector<uint8_t> blob;
      std::vector<uint32_t> map;
      ASSERT_TRUE(EncodeGeometry(in, o, &blob, &map).ok());
      Mesh out;
      ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
      EXPECT_TRUE(out.normals.empty());
      EXPECT_TRUE(out.colors.empty());
      EXPECT_LT(Compare(in, out, map).max_mm, 1.0);
    }
  }
}

TEST(GeometryCodec, EmptyAndDegenerateMeshes) {
  for (auto codec : {GeometryCodec::kG0, GeometryCodec::kG1}) {
    GeometryEncodeOptions o;
    o.codec = codec;
    std::vector<uint8_t> blob;
    ASSERT_TRUE(EncodeGeometry(Mesh{}, o, &blob).ok());
    Mesh out;
    ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
    EXPECT_TRUE(out.empty());

    Mesh d;  // a degenerate triangle and an unreferenced vertex
    d.positions = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}, {5, 5, 5}};
    d.triangles = {{0, 1, 2}, {0, 0, 1}};
    blob.clear();
    std::vector<uint32_t> map;
    ASSERT_TRUE(EncodeGeometry(d, o, &blob, &map).ok());
    const Status s = DecodeGeometry(blob, &out);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_EQ(out.num_triangles(), 2u);
  }
}

TEST(GeometryCodec, RejectsBadOptionsAndMeshes) {
  Mesh in = test::NoisySphere(10, 10);
  GeometryEncodeOptions o;
  o.position_step_m = 0;
  std::vector<uint8_t> blob;
  EXPECT_EQ(EncodeGeometry(in, o, &blob).code(), StatusCode::kInvalidArgument);
  o = {};
  in.triangles.push_back({0, 1, 100000});
  EXPECT_FALSE(EncodeGeometry(in, o, &blob).ok());
  Mesh huge;  // 200 m extent at 1 mm exceeds the 16-bit grid
  huge.positions = {{0, 0, 0}, {200, 0, 0}, {0, 1, 0}};
  huge.triangles = {{0, 1, 2}};
  const Status s = EncodeGeometry(huge, o, &blob);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("position step"), std::string::npos) << s.message();
}

TEST(GeometryCodec, OctahedralRoundTrip) {
  std::mt19937 rng(3);
  std::normal_distribution<float> g;
  for (int i = 0; i < 10000; ++i) {
    const Eigen::Vector3f n = Eigen::Vector3f(g(rng), g(rng), g(rng)).normalized();
    float u, v;
    OctEncode(n, &u, &v);
    EXPECT_GT(OctDecode(u, v).dot(n), 0.99999f);
  }
}

}  // namespace
}  // namespace holo::protocol
