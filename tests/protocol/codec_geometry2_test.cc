// G2 temporal geometry (protocol/geometry2_codec.h) on a fused-like moving
// sequence: a body with a swinging arm, re-extracted by marching tetrahedra
// every frame (so its topology changes every frame, as the site's fused mesh
// does), with a little per-frame surface noise like a re-fused TSDF.
// Regenerate the fuzz seeds with:
//   HOLO_WRITE_CORPUS=1 build/tests/protocol_codec_geometry2_test
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <unordered_map>

#include "common/metrics/triangle_index.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/geometry2_codec.h"

namespace holo::protocol {
namespace {

// Marching tetrahedra of a torso (sphere) with an arm (capsule) swinging by
// `frame`, at `voxel` metres.
Mesh MovingBody(int frame, float voxel) {
  const Eigen::Vector3f torso(0.0f, 0.0f, 1.5f);
  const float angle = 0.06f * static_cast<float>(frame);
  const Eigen::Vector3f shoulder(0.1f, 0.0f, 1.55f);
  const Eigen::Vector3f hand = shoulder + 0.2f * Eigen::Vector3f(std::cos(angle), std::sin(angle), -0.3f).normalized();
  auto sdf = [&](const Eigen::Vector3f& p) {
    const float body = (p - torso).norm() - 0.13f;
    const Eigen::Vector3f ab = hand - shoulder;
    const float h = std::clamp((p - shoulder).dot(ab) / ab.squaredNorm(), 0.0f, 1.0f);
    const float arm = (p - shoulder - h * ab).norm() - 0.035f;
    // Per-frame ripple of ±0.3 mm: a re-fused surface is never quite the same.
    const float ripple = 0.0003f * std::sin(40 * p.x() + 1.7f * frame) * std::sin(37 * p.y() - 1.3f * frame);
    return std::min(body, arm) + ripple;
  };
  const Eigen::Vector3f lo(-0.17f, -0.17f, 1.33f);
  const int nx = static_cast<int>(0.52f / voxel) + 1, ny = static_cast<int>(0.42f / voxel) + 1,
            nz = static_cast<int>(0.34f / voxel) + 1;
  auto id = [&](int i, int j, int k) { return (static_cast<size_t>(k) * ny + j) * nx + i; };
  auto pos = [&](int i, int j, int k) { return Eigen::Vector3f(lo + voxel * Eigen::Vector3f(i, j, k)); };
  std::vector<float> val(static_cast<size_t>(nx) * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) val[id(i, j, k)] = sdf(pos(i, j, k));
  Mesh m;
  std::unordered_map<uint64_t, uint32_t> edge_vertex;
  auto vertex = [&](size_t a, Eigen::Vector3f pa, size_t b, Eigen::Vector3f pb) {
    if (a > b) {
      std::swap(a, b);
      std::swap(pa, pb);
    }
    const uint64_t key = (static_cast<uint64_t>(a) << 32) | b;
    if (auto it = edge_vertex.find(key); it != edge_vertex.end()) return it->second;
    const float va = val[a], vb = val[b];
    const auto idx = static_cast<uint32_t>(m.positions.size());
    m.positions.push_back(pa + (va / (va - vb)) * (pb - pa));
    m.colors.push_back({static_cast<uint8_t>(100 + idx % 50), 120, 140});
    edge_vertex.emplace(key, idx);
    return idx;
  };
  static constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  static constexpr int kTets[6][4] = {{0, 5, 1, 6}, {0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6}, {0, 7, 4, 6}, {0, 4, 5, 6}};
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        size_t cid[8];
        Eigen::Vector3f cp[8];
        int inside = 0;
        for (int c = 0; c < 8; ++c) {
          cid[c] = id(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          cp[c] = pos(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          inside += val[cid[c]] < 0;
        }
        if (inside == 0 || inside == 8) continue;
        for (const auto& tet : kTets) {
          std::vector<int> in, out;
          for (int c : tet) (val[cid[c]] < 0 ? in : out).push_back(c);
          if (in.empty() || out.empty()) continue;
          Eigen::Vector3f gin = Eigen::Vector3f::Zero(), gout = Eigen::Vector3f::Zero();
          for (int c : in) gin += cp[c] / static_cast<float>(in.size());
          for (int c : out) gout += cp[c] / static_cast<float>(out.size());
          const Eigen::Vector3f outward = gout - gin;
          auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
            if (a == b || b == c || a == c) return;
            const Eigen::Vector3f n = (m.positions[b] - m.positions[a]).cross(m.positions[c] - m.positions[a]);
            if (n.dot(outward) < 0) std::swap(b, c);
            m.triangles.push_back({a, b, c});
          };
          auto v = [&](int a, int b) { return vertex(cid[a], cp[a], cid[b], cp[b]); };
          if (in.size() == 1 || in.size() == 3) {
            const int s = in.size() == 1 ? in[0] : out[0];
            const std::vector<int>& o = in.size() == 1 ? out : in;
            emit(v(s, o[0]), v(s, o[1]), v(s, o[2]));
          } else {
            const uint32_t a = v(in[0], out[0]), b = v(in[0], out[1]), c = v(in[1], out[1]), d = v(in[1], out[0]);
            emit(a, b, c);
            emit(a, c, d);
          }
        }
      }
  return m;
}

// Two-sided RMS point-to-surface distance (vertices of each to the other's
// surface), metres: the bench's measure.
double TwoSidedRms(const Mesh& a, const Mesh& b) {
  auto ia = metrics::TriangleIndex::Build(a);
  auto ib = metrics::TriangleIndex::Build(b);
  EXPECT_TRUE(ia.ok() && ib.ok());
  double se = 0;
  for (const auto& p : a.positions) se += std::pow(std::min(ib->Query(p, 0.05f).distance, 0.05f), 2);
  for (const auto& p : b.positions) se += std::pow(std::min(ia->Query(p, 0.05f).distance, 0.05f), 2);
  return std::sqrt(se / static_cast<double>(a.num_vertices() + b.num_vertices()));
}

struct Coded {
  std::vector<std::vector<uint8_t>> blobs;
  std::vector<Geometry2FrameInfo> infos;
  std::vector<Mesh> inputs;
};

Coded EncodeSequence(int frames, float voxel, const Geometry2EncodeOptions& o = {}) {
  Coded c;
  Geometry2Encoder enc(o);
  for (int f = 0; f < frames; ++f) {
    c.inputs.push_back(MovingBody(f, voxel));
    c.blobs.emplace_back();
    c.infos.emplace_back();
    EXPECT_TRUE(enc.Encode(c.inputs.back(), &c.blobs.back(), &c.infos.back()).ok());
  }
  return c;
}

// The sanitizer build (ASan+UBSan, -O1) runs the encoder ~50× slower: fewer
// frames there, the same code paths.
#if defined(__SANITIZE_ADDRESS__)
constexpr int kSequenceFrames = 5;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr int kSequenceFrames = 5;
#else
constexpr int kSequenceFrames = 8;
#endif
#else
constexpr int kSequenceFrames = 8;
#endif

// One coded sequence shared by the tests (14 mm voxels; S8-QVGA fuses at 8).
const Coded& Sequence() {
  static const Coded c = EncodeSequence(kSequenceFrames, 0.014f);
  return c;
}
// A small one (16 mm) for the every-prefix and bit-flip tests.
const Coded& SmallSequence() {
  static const Coded c = EncodeSequence(3, 0.02f);
  return c;
}

bool SameMesh(const Mesh& a, const Mesh& b) {
  return a.positions == b.positions && a.normals == b.normals && a.colors == b.colors && a.triangles == b.triangles;
}

// Two bodies side by side: the second one appears or vanishes.
Mesh TwoBodies(int frame, float voxel) {
  Mesh two = MovingBody(frame, voxel);
  const Mesh other = MovingBody(frame, voxel);
  const auto base = static_cast<uint32_t>(two.positions.size());
  for (const auto& p : other.positions) two.positions.push_back(p + Eigen::Vector3f(0.6f, 0, 0));
  two.colors.insert(two.colors.end(), other.colors.begin(), other.colors.end());
  for (auto t : other.triangles) two.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  return two;
}

TEST(Geometry2Codec, MovingSequenceRoundTripWithinTheBound) {
  const Coded& c = Sequence();
  Geometry2Encoder enc;  // a second encoder: the encoder's view of the decoded meshes
  Geometry2Decoder dec;
  int predicted = 0;
  size_t key_bytes = 0, pred_bytes = 0;
  for (size_t f = 0; f < c.blobs.size(); ++f) {
    Mesh out, expected;
    std::vector<uint8_t> again;
    ASSERT_TRUE(enc.Encode(c.inputs[f], &again).ok());
    EXPECT_EQ(again, c.blobs[f]) << "the encoder is deterministic, frame " << f;
    enc.DecodedMesh(&expected);
    const Status s = dec.Decode(c.blobs[f], &out);
    ASSERT_TRUE(s.ok()) << f << ": " << s.ToString();
    // The decoder reproduces the encoder's reference bit for bit.
    EXPECT_TRUE(SameMesh(out, expected)) << "frame " << f;
    ASSERT_TRUE(CheckMesh(out).ok());
    const double rms = TwoSidedRms(out, c.inputs[f]);
    EXPECT_LE(rms, Geometry2EncodeOptions{}.max_rms_m * 1.01) << "frame " << f;
    if (!c.infos[f].keyframe) {
      ++predicted;
      pred_bytes += c.blobs[f].size();
      EXPECT_NEAR(rms, c.infos[f].rms_m, 1e-6) << "the encoder's check measures what the viewer gets, frame " << f;
      // The topology is the keyframe's, although the input's changes every frame.
      EXPECT_NE(out.num_vertices(), c.inputs[f].num_vertices());
    } else {
      key_bytes += c.blobs[f].size();
    }
  }
  EXPECT_TRUE(c.infos[0].keyframe);
  EXPECT_EQ(c.infos[0].reason, "first");
  EXPECT_GE(predicted, kSequenceFrames / 2 + 1) << "a slowly moving body should mostly be predicted";
  const size_t keyframes = c.blobs.size() - predicted;
  EXPECT_LT(pred_bytes / predicted, key_bytes / keyframes / 4) << "predicted frames must be far smaller than keyframes";
}

TEST(Geometry2Codec, KeyframeWhenTheShapeChangesTooMuchOrOnRequest) {
  Geometry2Encoder enc;
  std::vector<uint8_t> blob;
  Geometry2FrameInfo info;
  ASSERT_TRUE(enc.Encode(MovingBody(0, 0.016f), &blob, &info).ok());
  EXPECT_TRUE(info.keyframe);
  // The arm jumps by 0.6 rad (12 cm at the hand): its clusters' rigid
  // motions follow it.
  ASSERT_TRUE(enc.Encode(MovingBody(10, 0.016f), &blob, &info).ok());
  EXPECT_FALSE(info.keyframe) << info.reason;
  EXPECT_LT(info.rms_m, Geometry2EncodeOptions{}.max_rms_m);
  // A part that appears (a second body) cannot be predicted: a keyframe.
  const Mesh two = TwoBodies(11, 0.016f);
  ASSERT_TRUE(enc.Encode(two, &blob, &info).ok());
  EXPECT_TRUE(info.keyframe);
  EXPECT_TRUE(info.reason == "rms" || info.reason == "far") << info.reason;
  EXPECT_GT(info.rms_m, Geometry2EncodeOptions{}.max_rms_m);
  ASSERT_TRUE(enc.Encode(two, &blob, &info).ok());
  EXPECT_FALSE(info.keyframe) << info.reason;
  enc.RequestKeyframe();
  ASSERT_TRUE(enc.Encode(MovingBody(12, 0.016f), &blob, &info).ok());
  EXPECT_TRUE(info.keyframe);
  EXPECT_EQ(info.reason, "requested");
  // Group length.
  Geometry2EncodeOptions o;
  o.max_group_frames = 2;
  Geometry2Encoder short_groups(o);
  std::vector<bool> key;
  for (int f = 0; f < 5; ++f) {
    ASSERT_TRUE(short_groups.Encode(MovingBody(f, 0.016f), &blob, &info).ok());
    key.push_back(info.keyframe);
  }
  EXPECT_EQ(key, (std::vector<bool>{true, false, true, false, true}));
}

TEST(Geometry2Codec, BacksOffOnContentThatNeverPredicts) {
  for (bool backoff : {true, false}) {
    Geometry2EncodeOptions o;
    o.backoff = backoff;
    Geometry2Encoder enc(o);
    std::vector<std::string> reasons;
    for (int f = 0; f < 8; ++f) {
      std::vector<uint8_t> blob;
      Geometry2FrameInfo info;
      ASSERT_TRUE(enc.Encode(f % 2 ? TwoBodies(0, 0.025f) : MovingBody(0, 0.025f), &blob, &info).ok());
      ASSERT_TRUE(info.keyframe);
      reasons.push_back(info.reason == "far" ? "rms" : info.reason);
    }
    if (backoff) {
      EXPECT_EQ(reasons, (std::vector<std::string>{"first", "rms", "backoff", "rms", "backoff", "backoff", "backoff", "rms"}));
    } else {
      EXPECT_EQ(std::count(reasons.begin(), reasons.end(), "backoff"), 0);
    }
  }
}

TEST(Geometry2Codec, ViewerJoiningMidStreamDecodesFromTheNextKeyframe) {
  const Coded& c = Sequence();
  Geometry2Decoder full, late;
  Mesh a, b;
  bool synced = false;
  for (size_t f = 0; f < c.blobs.size(); ++f) {
    ASSERT_TRUE(full.Decode(c.blobs[f], &a).ok());
    if (f < 3) continue;  // the late viewer joins at frame 3
    const Status s = late.Decode(c.blobs[f], &b);
    if (!synced && !c.infos[f].keyframe) {
      EXPECT_EQ(s.code(), StatusCode::kNotFound);
      EXPECT_NE(s.message().find("no keyframe"), std::string::npos) << s.message();
      EXPECT_TRUE(b.positions.empty());
      continue;
    }
    ASSERT_TRUE(s.ok()) << s.ToString();
    synced = true;
    EXPECT_TRUE(SameMesh(a, b)) << f;
  }
  // With a keyframe on request, the join is immediate.
  Geometry2Encoder enc;
  std::vector<uint8_t> blob;
  for (int f = 0; f < 3; ++f) ASSERT_TRUE(enc.Encode(MovingBody(f, 0.016f), &blob).ok());
  enc.RequestKeyframe();
  blob.clear();
  ASSERT_TRUE(enc.Encode(MovingBody(3, 0.016f), &blob).ok());
  Geometry2Decoder fresh;
  EXPECT_TRUE(fresh.Decode(blob, &b).ok());
}

TEST(Geometry2Codec, RefusesAPredictedFrameWithoutItsReference) {
  const Coded& c = Sequence();
  ASSERT_FALSE(c.infos[1].keyframe);
  ASSERT_FALSE(c.infos[2].keyframe);
  Mesh m;
  {  // a lost frame: 0 then 2
    Geometry2Decoder d;
    ASSERT_TRUE(d.Decode(c.blobs[0], &m).ok());
    const Status s = d.Decode(c.blobs[2], &m);
    EXPECT_EQ(s.code(), StatusCode::kNotFound);
    EXPECT_NE(s.message().find("frame counter mismatch"), std::string::npos) << s.message();
    EXPECT_TRUE(m.positions.empty());
    // Its reference is intact: frame 1 still decodes.
    EXPECT_TRUE(d.Decode(c.blobs[1], &m).ok());
  }
  {  // another stream's keyframe
    Geometry2EncodeOptions o;
    Geometry2Encoder other(o);
    std::vector<uint8_t> k;
    ASSERT_TRUE(other.Encode(MovingBody(0, 0.016f), &k).ok());
    ASSERT_TRUE(other.Encode(MovingBody(0, 0.016f), &k).ok());  // keyframe id 1 again, then...
    other.RequestKeyframe();
    k.clear();
    ASSERT_TRUE(other.Encode(MovingBody(0, 0.016f), &k).ok());  // keyframe id 2
    Geometry2Decoder d;
    ASSERT_TRUE(d.Decode(k, &m).ok());
    const Status s = d.Decode(c.blobs[1], &m);
    EXPECT_EQ(s.code(), StatusCode::kNotFound);
    EXPECT_NE(s.message().find("keyframe id mismatch"), std::string::npos) << s.message();
  }
  {  // same ids, different reference (another encoder's keyframe 1)
    Geometry2Encoder other;
    std::vector<uint8_t> k;
    ASSERT_TRUE(other.Encode(MovingBody(0, 0.016f), &k).ok());
    Geometry2Decoder d;
    ASSERT_TRUE(d.Decode(k, &m).ok());
    const Status s = d.Decode(c.blobs[1], &m);
    EXPECT_EQ(s.code(), StatusCode::kNotFound);
    EXPECT_NE(s.message().find("vertex count mismatch"), std::string::npos) << s.message();
  }
  {  // a tampered reference hash
    Geometry2Decoder d;
    ASSERT_TRUE(d.Decode(c.blobs[0], &m).ok());
    std::vector<uint8_t> bad = c.blobs[1];
    bad[16] ^= 1;
    const Status s = d.Decode(bad, &m);
    EXPECT_EQ(s.code(), StatusCode::kNotFound);
    EXPECT_NE(s.message().find("reference hash"), std::string::npos) << s.message();
  }
  {  // after Reset only a keyframe decodes
    Geometry2Decoder d;
    ASSERT_TRUE(d.Decode(c.blobs[0], &m).ok());
    d.Reset();
    EXPECT_FALSE(d.has_reference());
    EXPECT_EQ(d.Decode(c.blobs[1], &m).code(), StatusCode::kNotFound);
  }
}

TEST(Geometry2Codec, EveryPrefixIsRefusedAndLeavesTheReference) {
  const Coded& c = SmallSequence();
  ASSERT_TRUE(c.infos[0].keyframe);
  ASSERT_FALSE(c.infos[1].keyframe) << c.infos[1].reason;
  Mesh m;
  for (size_t f = 0; f < 2; ++f) {
    const std::vector<uint8_t>& blob = c.blobs[f];
    Geometry2Decoder d;
    if (f == 1) {
      ASSERT_TRUE(d.Decode(c.blobs[0], &m).ok());
    }
    for (size_t n = 0; n < blob.size(); ++n) {
      // A fresh heap buffer of exactly n bytes, so that ASan sees any overrun.
      std::unique_ptr<uint8_t[]> buf(new uint8_t[std::max<size_t>(n, 1)]);
      std::copy(blob.begin(), blob.begin() + static_cast<std::ptrdiff_t>(n), buf.get());
      const Status s = d.Decode(std::span<const uint8_t>(buf.get(), n), &m);
      ASSERT_FALSE(s.ok()) << "frame " << f << " prefix " << n;
      EXPECT_TRUE(m.positions.empty());
    }
    EXPECT_TRUE(d.Decode(blob, &m).ok()) << "frame " << f << " after its prefixes";
  }
}

TEST(Geometry2Codec, BitFlipsAreRefusedOrGiveAValidMesh) {
  const Coded& c = SmallSequence();
  Mesh m;
  int refused = 0, accepted = 0;
  for (size_t f = 0; f < 2; ++f) {
    const std::vector<uint8_t>& blob = c.blobs[f];
    const size_t bits = blob.size() * 8;
    // Every header bit, then a sample (the G1 part has its own tests).
    for (size_t bit = 0; bit < bits; bit += (bit < 256 ? 1 : (f == 0 ? 211 : 13))) {
      Geometry2Decoder d;
      if (f == 1) {
      ASSERT_TRUE(d.Decode(c.blobs[0], &m).ok());
    }
      std::vector<uint8_t> bad = blob;
      bad[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
      if (d.Decode(bad, &m).ok()) {
        ASSERT_TRUE(CheckMesh(m).ok()) << "bit " << bit;
        ++accepted;
      } else {
        EXPECT_TRUE(m.positions.empty());
        ++refused;
      }
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(accepted + refused, 200);
}

TEST(Geometry2Codec, NormalsFollowTheIntegerRule) {
  // A single right triangle in the z = 0 plane: every vertex normal is +Z exactly,
  // and a displacement of k steps moves each vertex by exactly k·step along +Z.
  Mesh tri;
  tri.positions = {{0, 0, 0}, {0.05f, 0, 0}, {0, 0.05f, 0}};
  tri.triangles = {{0, 1, 2}};
  Geometry2Encoder enc;
  std::vector<uint8_t> blob;
  ASSERT_TRUE(enc.Encode(tri, &blob).ok());
  Mesh moved = tri;
  for (auto& p : moved.positions) p.z() += 0.003f;
  Geometry2FrameInfo info;
  std::vector<uint8_t> blob2;
  ASSERT_TRUE(enc.Encode(moved, &blob2, &info).ok());
  ASSERT_FALSE(info.keyframe) << info.reason;
  Geometry2Decoder dec;
  Mesh a, b;
  ASSERT_TRUE(dec.Decode(blob, &a).ok());
  ASSERT_TRUE(dec.Decode(blob2, &b).ok());
  for (size_t v = 0; v < 3; ++v) {
    EXPECT_EQ(b.normals[v], Eigen::Vector3f::UnitZ());
    EXPECT_EQ(b.positions[v].x(), a.positions[v].x());
    EXPECT_EQ(b.positions[v].y(), a.positions[v].y());
    EXPECT_NEAR(b.positions[v].z() - a.positions[v].z(), 0.003f, 1e-6f);
  }
}

TEST(Geometry2Codec, RejectsBadOptionsAndMeshes) {
  Geometry2EncodeOptions o;
  o.displacement_step_m = 0;
  EXPECT_FALSE(o.Check().ok());
  o = {};
  o.max_group_frames = 0;
  EXPECT_FALSE(o.Check().ok());
  o = {};
  o.keyframe.codec = GeometryCodec::kG0;
  EXPECT_FALSE(o.Check().ok());
  o.max_group_frames = 0;
  Geometry2Encoder bad(o);
  std::vector<uint8_t> blob;
  EXPECT_EQ(bad.Encode(MovingBody(0, 0.02f), &blob).code(), StatusCode::kInvalidArgument);
  Geometry2Encoder enc;
  Mesh broken = MovingBody(0, 0.02f);
  broken.triangles.push_back({0, 1, 999999});
  EXPECT_EQ(enc.Encode(broken, &blob).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(blob.empty());
  // Not G2 at all.
  Geometry2Decoder d;
  Mesh m;
  std::vector<uint8_t> g1;
  ASSERT_TRUE(EncodeGeometry(MovingBody(0, 0.02f), {}, &g1).ok());
  const Status s = d.Decode(g1, &m);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("g2.codec"), std::string::npos) << s.message();
}

// Seeds of holoport-fuzz-geometry2 (protocol/fuzz/corpus/geometry2): a keyframe
// and its predicted frames, as one stream.
TEST(Geometry2Codec, FuzzSeedsDecode) {
  const Coded& c = SmallSequence();
  const std::string dir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/geometry2";
  const std::vector<uint8_t> seed = Geometry2FuzzInput(c.blobs);
  if (std::getenv("HOLO_WRITE_CORPUS")) {
    std::filesystem::create_directories(dir);
    std::ofstream(dir + "/seed-geometry2-stream", std::ios::binary)
        .write(reinterpret_cast<const char*>(seed.data()), static_cast<std::streamsize>(seed.size()));
  }
  EXPECT_EQ(FuzzGeometry2(seed), 3);
  int seeds = 0;
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int decoded = FuzzGeometry2(bytes);  // must not crash
    if (entry.path().filename().string().rfind("seed-", 0) == 0) {
      EXPECT_GE(decoded, 2) << entry.path();
      ++seeds;
    }
  }
  EXPECT_GE(seeds, 1);
}

}  // namespace
}  // namespace holo::protocol
