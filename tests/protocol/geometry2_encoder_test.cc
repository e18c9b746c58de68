// G2 temporal geometry (protocol/geometry2_codec.h), the encoder's side: round
// trips within the bound on a fused-like moving sequence, keyframe decisions,
// back-off, a viewer joining mid-stream. Not a sanitizer test (the encoder is
// ~50x slower under ASan); the decoder's refusals are in codec_geometry2_test.cc.
#include <gtest/gtest.h>

#include "protocol/geometry2_fixture.h"  // tests/protocol/

namespace holo::protocol {
namespace {

using namespace g2test;

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
  EXPECT_GE(predicted, static_cast<int>(c.blobs.size()) / 2 + 1) << "a slowly moving body should mostly be predicted";
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

}  // namespace
}  // namespace holo::protocol
