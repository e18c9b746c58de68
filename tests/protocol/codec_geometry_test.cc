#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <random>

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
  auto canon = [](std::array<uint32_t, 3> t) {  // the smallest rotation (also for repeated indices)
    return std::min({t, std::array<uint32_t, 3>{t[1], t[2], t[0]}, std::array<uint32_t, 3>{t[2], t[0], t[1]}});
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
    o.normals = NormalMode::kTransmit;
    o.chroma_shift = 0;  // lossless colours
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
  // The target is 1/8 of G0's bytes; a smooth sphere does far better.
  EXPECT_LT(g1.size() * 8, g0.size()) << "G0 " << g0.size() << " G1 " << g1.size();
}

TEST(GeometryCodec, WithoutNormalsOrColorsAndOptions) {
  Mesh in = test::NoisySphere(20, 30);
  in.normals.clear();
  in.colors.clear();
  for (auto codec : {GeometryCodec::kG0, GeometryCodec::kG1}) {
    for (NormalMode mode : {NormalMode::kNone, NormalMode::kTransmit, NormalMode::kRecompute}) {
      GeometryEncodeOptions o;
      o.codec = codec;
      o.normals = mode;
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

TEST(GeometryCodec, G1RecomputedNormalsWithinAngleBound) {
  // Default G1 sends no normals; the decoder rebuilds area-weighted normals
  // from the quantized triangles. The input's normals are area-weighted too,
  // so the difference is the effect of quantization only.
  const Mesh in = test::NoisySphere(60, 90);
  std::vector<uint8_t> sent, recomputed;
  std::vector<uint32_t> map;
  GeometryEncodeOptions o;
  ASSERT_EQ(o.normals, NormalMode::kRecompute);
  ASSERT_TRUE(EncodeGeometry(in, o, &recomputed, &map).ok());
  o.normals = NormalMode::kTransmit;
  ASSERT_TRUE(EncodeGeometry(in, o, &sent).ok());
  EXPECT_LT(recomputed.size() + in.num_vertices(), sent.size()) << "omitting normals must save > 1 byte per vertex";
  Mesh out;
  const Status s = DecodeGeometry(recomputed, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_EQ(out.normals.size(), out.num_vertices());
  // The decoder's normals are RecomputeNormals of the decoded mesh; against
  // RecomputeNormals of the unquantized input they differ by the effect of
  // the 1 mm grid alone. Triangles here are 1-2 cm (3 mm near the poles): a
  // 1 mm grid tilts a 2 cm face by up to ~2.5°, a pole face by far more.
  Mesh ref = in;
  RecomputeNormals(&ref);
  std::vector<double> deg;
  for (size_t i = 0; i < in.num_vertices(); ++i) {
    const float c = std::clamp(ref.normals[i].dot(out.normals[map[i]]), -1.0f, 1.0f);
    deg.push_back(std::acos(c) * 180.0 / M_PI);
  }
  std::sort(deg.begin(), deg.end());
  double sum = 0;
  for (double d : deg) sum += d;
  std::printf("recomputed normals vs unquantized: mean %.2f°, p99 %.2f°, max %.2f°\n", sum / deg.size(),
              deg[deg.size() * 99 / 100], deg.back());
  EXPECT_LT(sum / deg.size(), 1.0);
  EXPECT_LT(deg[deg.size() * 99 / 100], 4.0);
  EXPECT_LT(deg.back(), 10.0);
  for (const auto& n : out.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-5f);
  ExpectSameConnectivity(in, out, map);

  // RecomputeNormals is what the decoder does: on the decoded mesh it reproduces the decoded normals.
  Mesh copy = out;
  RecomputeNormals(&copy);
  for (size_t i = 0; i < out.num_vertices(); ++i) EXPECT_GT(copy.normals[i].dot(out.normals[i]), 0.99999f);
}

TEST(GeometryCodec, G1RecomputeFlagWithoutInputNormalsSendsNone) {
  Mesh in = test::NoisySphere(10, 12);
  in.normals.clear();
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeGeometry(in, {}, &blob).ok());
  EXPECT_EQ(blob[1] & 0x04, 0);  // flags: no recompute bit
  Mesh out;
  ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
  EXPECT_TRUE(out.normals.empty());
}

TEST(GeometryCodec, G1RefusesNormalsSentAndRecomputed) {
  const Mesh in = test::NoisySphere(6, 9);
  GeometryEncodeOptions o;
  o.normals = NormalMode::kTransmit;
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeGeometry(in, o, &blob).ok());
  blob[1] |= 0x04;
  Mesh out;
  EXPECT_EQ(DecodeGeometry(blob, &out).code(), StatusCode::kDataLoss);
}

// Meshes the traversal must handle beyond a closed manifold: several
// components, open borders, a non-manifold fan, repeated triangles, shared
// vertices across components, degenerate triangles, and a triangle soup.
TEST(GeometryCodec, G1ConnectivityOfAwkwardMeshes) {
  std::vector<Mesh> meshes;
  {
    Mesh a = test::NoisySphere(8, 10);
    const Mesh b = test::NoisySphere(5, 7, 0.1f, {1, 0, 1});
    const auto n = static_cast<uint32_t>(a.positions.size());
    a.positions.insert(a.positions.end(), b.positions.begin(), b.positions.end());
    a.colors.insert(a.colors.end(), b.colors.begin(), b.colors.end());
    a.normals.insert(a.normals.end(), b.normals.begin(), b.normals.end());
    for (auto t : b.triangles) a.triangles.push_back({t[0] + n, t[1] + n, t[2] + n});
    meshes.push_back(a);
  }
  {
    Mesh open = test::NoisySphere(12, 16);  // drop a band of triangles: two holes
    open.triangles.erase(open.triangles.begin() + 40, open.triangles.begin() + 90);
    meshes.push_back(open);
  }
  {
    Mesh fan;  // five triangles sharing one edge (non-manifold), plus a repeated and a flipped triangle
    fan.positions = {{0, 0, 0}, {0, 0, 1}};
    for (int i = 0; i < 5; ++i) fan.positions.push_back({std::cos(i * 1.2f), std::sin(i * 1.2f), 0.5f});
    for (uint32_t i = 0; i < 5; ++i) fan.triangles.push_back({0, 1, 2 + i});
    fan.triangles.push_back({0, 1, 2});
    fan.triangles.push_back({1, 0, 3});
    fan.triangles.push_back({2, 2, 2});
    meshes.push_back(fan);
  }
  {
    std::mt19937 rng(5);  // a random triangle soup over few vertices
    std::uniform_int_distribution<uint32_t> v(0, 29);
    std::uniform_real_distribution<float> p(0, 0.5f);
    Mesh soup;
    for (int i = 0; i < 30; ++i) soup.positions.push_back({p(rng), p(rng), p(rng)});
    for (int i = 0; i < 400; ++i) soup.triangles.push_back({v(rng), v(rng), v(rng)});
    meshes.push_back(soup);
  }
  for (size_t k = 0; k < meshes.size(); ++k) {
    const Mesh& in = meshes[k];
    std::vector<uint8_t> blob;
    std::vector<uint32_t> map;
    ASSERT_TRUE(EncodeGeometry(in, {}, &blob, &map).ok()) << "mesh " << k;
    Mesh out;
    const Status s = DecodeGeometry(blob, &out);
    ASSERT_TRUE(s.ok()) << "mesh " << k << ": " << s.ToString();
    ASSERT_TRUE(CheckMesh(out).ok());
    ASSERT_EQ(out.num_triangles(), in.num_triangles()) << "mesh " << k;
    EXPECT_LT(Compare(in, out, map).max_mm, 0.87) << "mesh " << k;
    EXPECT_LE(Compare(in, out, map).color_max, 1) << "mesh " << k;  // default chroma_shift 1
    ExpectSameConnectivity(in, out, map);
  }
}

TEST(GeometryCodec, G1ConnectivityBitsPerTriangle) {
  // A regular closed mesh: the traversal should need well under 3 bits per triangle.
  const Mesh in = test::NoisySphere(150, 200);
  GeometryEncodeOptions o;
  o.colors = false;
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeGeometry(in, o, &blob).ok());
  uint32_t conn = 0;
  std::memcpy(&conn, blob.data() + 29, 4);
  EXPECT_LT(conn * 8.0 / in.num_triangles(), 3.0) << conn << " bytes for " << in.num_triangles() << " triangles";
}

TEST(GeometryCodec, G1CountsBeyondWhatTheBytesCanHoldAreRefused) {
  const Mesh in = test::NoisySphere(6, 9);
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeGeometry(in, {}, &blob).ok());
  std::vector<uint8_t> b = blob;
  const uint32_t nt = 4u << 20, nv = 2u << 20;
  std::memcpy(b.data() + 8, &nt, 4);
  Mesh out;
  Status s = DecodeGeometry(b, &out);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("cannot fit"), std::string::npos) << s.message();
  b = blob;
  std::memcpy(b.data() + 4, &nv, 4);
  s = DecodeGeometry(b, &out);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_TRUE(out.empty());
}

TEST(GeometryCodec, G1ColourPredictorFollowsTheColours) {
  // Flag bit 3: colours predicted by the mean (noisy colours) or by the
  // parallelogram (smooth colours). Both are lossless.
  Mesh smooth = test::NoisySphere(30, 40);
  for (size_t i = 0; i < smooth.num_vertices(); ++i) {
    const Eigen::Vector3f& p = smooth.positions[i];
    smooth.colors[i] = {static_cast<uint8_t>(100 + 300 * (p.x() - 0.2f)), static_cast<uint8_t>(120 + 300 * (p.y() + 0.1f)),
                        static_cast<uint8_t>(100 + 300 * (p.z() - 1.1f))};
  }
  Mesh noisy = smooth;
  std::mt19937 rng(9);
  for (auto& c : noisy.colors) c = {static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng())};
  for (const auto& [mesh, by_mean] : {std::pair{smooth, false}, std::pair{noisy, true}}) {
    std::vector<uint8_t> blob;
    std::vector<uint32_t> map;
    GeometryEncodeOptions o;
    o.chroma_shift = 0;
    ASSERT_TRUE(EncodeGeometry(mesh, o, &blob, &map).ok());
    EXPECT_EQ((blob[1] & 0x08) != 0, by_mean);
    Mesh out;
    ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
    EXPECT_EQ(Compare(mesh, out, map).color_max, 0);
  }
}

TEST(GeometryCodec, G1ChromaQuantizationErrorBound) {
  // Co and Cg on multiples of 2^s: B exact, R and G within 2^(s-1), except
  // where Y had to be clamped (saturated colours), which may add one level.
  Mesh in = test::NoisySphere(30, 40);
  std::mt19937 rng(4);
  for (auto& c : in.colors) c = {static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng()), static_cast<uint8_t>(rng())};
  for (int shift = 0; shift <= 3; ++shift) {
    GeometryEncodeOptions o;
    o.chroma_shift = shift;
    std::vector<uint8_t> blob;
    std::vector<uint32_t> map;
    ASSERT_TRUE(EncodeGeometry(in, o, &blob, &map).ok());
    Mesh out;
    ASSERT_TRUE(DecodeGeometry(blob, &out).ok());
    int err[3] = {0, 0, 0};
    for (size_t i = 0; i < in.num_vertices(); ++i)
      for (int c = 0; c < 3; ++c) err[c] = std::max(err[c], std::abs(in.colors[i][c] - out.colors[map[i]][c]));
    const int half = shift ? 1 << (shift - 1) : 0;
    EXPECT_LE(err[0], half + (shift ? 1 : 0)) << "shift " << shift;
    EXPECT_LE(err[1], half + (shift ? 1 : 0)) << "shift " << shift;
    EXPECT_LE(err[2], shift ? 1 : 0) << "shift " << shift;
    std::printf("chroma_shift %d: max error R %d G %d B %d, %zu bytes\n", shift, err[0], err[1], err[2], blob.size());
  }
  GeometryEncodeOptions o;
  o.chroma_shift = 4;
  std::vector<uint8_t> blob;
  EXPECT_EQ(EncodeGeometry(in, o, &blob).code(), StatusCode::kInvalidArgument);
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
