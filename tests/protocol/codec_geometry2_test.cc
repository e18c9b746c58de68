// G2 temporal geometry (protocol/geometry2_codec.h), the decoder's side
// (also under ASan+UBSan; the encoder's behaviour is in
// geometry2_encoder_test.cc), on a fused-like moving
// sequence: a body with a swinging arm, re-extracted by marching tetrahedra
// every frame (so its topology changes every frame, as the site's fused mesh
// does), with a little per-frame surface noise like a re-fused TSDF.
// Regenerate the fuzz seeds with:
//   HOLO_WRITE_CORPUS=1 build/tests/protocol_codec_geometry2_test
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "protocol/fuzz_decoders.h"
#include "protocol/geometry2_fixture.h"  // tests/protocol/

namespace holo::protocol {
namespace {

using namespace g2test;

TEST(Geometry2Codec, RefusesAPredictedFrameWithoutItsReference) {
  const Coded& c = SmallSequence();
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
