#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <set>

#include "protocol/byte_io.h"
#include "protocol/messages.h"
#include "protocol/sample_messages.h"

namespace holo::protocol {
namespace {

void ExpectRigNear(const Rig& a, const Rig& b) {
  EXPECT_EQ(a.name, b.name);
  ASSERT_EQ(a.pods.size(), b.pods.size());
  for (size_t i = 0; i < a.pods.size(); ++i) {
    EXPECT_EQ(a.pods[i].id, b.pods[i].id);
    EXPECT_EQ(a.pods[i].name, b.pods[i].name);
    EXPECT_EQ(a.pods[i].color.distortion, b.pods[i].color.distortion);
    EXPECT_EQ(a.pods[i].depth.fx, b.pods[i].depth.fx);
    EXPECT_TRUE(a.pods[i].world_from_depth.isApprox(b.pods[i].world_from_depth));
  }
}

void ExpectSame(const Payload& a, const Payload& b) {
  ASSERT_EQ(a.index(), b.index());
  if (const auto* ra = std::get_if<RigMessage>(&a)) {
    ExpectRigNear(ra->rig, std::get<RigMessage>(b).rig);
    return;
  }
  std::visit(
      [&](const auto& x) {
        using T = std::decay_t<decltype(x)>;
        if constexpr (!std::is_same_v<T, RigMessage>) {
          EXPECT_TRUE(x == std::get<T>(b)) << MessageTypeName(TypeOf(a));
        }
      },
      a);
}

TEST(ProtocolMessages, GoldenHeaderBytes) {
  Header h;
  h.type = MessageType::kMeshFrame;
  h.flags = kFlagKeyFrame;
  h.stream_id = 0x01020304;
  h.sequence = 0xA0B0C0D0;
  h.capture_time_us = 0x1122334455667788;
  h.payload_length = 0x000BCDEF;
  uint8_t bytes[kHeaderSize];
  EncodeHeader(h, bytes);
  const uint8_t golden[kHeaderSize] = {
      'H',  'L',  'P',  'T',                           // magic
      0x01, 0x00,                                      // version 1
      0x05, 0x00,                                      // type mesh_frame
      0x02, 0x00,                                      // flags: key frame
      0x00, 0x00,                                      // reserved
      0x04, 0x03, 0x02, 0x01,                          // stream id
      0xD0, 0xC0, 0xB0, 0xA0,                          // sequence
      0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11,  // capture time µs
      0xEF, 0xCD, 0x0B, 0x00,                          // payload length
  };
  EXPECT_EQ(0, std::memcmp(bytes, golden, kHeaderSize));
  auto back = DecodeHeader(golden, kHeaderSize);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, h);
}

TEST(ProtocolMessages, GoldenPingMessage) {
  Header h;
  h.sequence = 1;
  const std::vector<uint8_t> m = EncodeMessage(h, Ping{0x0102030405060708ull, 1000});
  const std::vector<uint8_t> golden = {'H', 'L', 'P', 'T', 1, 0, 11, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                       1,   0,   0,   0,   0, 0, 0,  0, 0, 0, 0, 0, 16, 0, 0, 0,
                                       8,   7,   6,   5,   4, 3, 2,  1, 0xE8, 3, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(m, golden);
}

TEST(ProtocolMessages, RoundTripEveryType) {
  const auto samples = test::SamplePayloads();
  std::set<size_t> types;
  for (const Payload& p : samples) {
    Header h;
    h.stream_id = 3;
    h.sequence = 17;
    h.capture_time_us = 5555;
    const std::vector<uint8_t> bytes = EncodeMessage(h, p);
    auto m = DecodeMessage(bytes);
    ASSERT_TRUE(m.ok()) << MessageTypeName(TypeOf(p)) << ": " << m.status().ToString();
    EXPECT_EQ(m->header.type, TypeOf(p));
    EXPECT_EQ(m->header.stream_id, 3u);
    EXPECT_EQ(m->header.sequence, 17u);
    EXPECT_EQ(m->header.capture_time_us, 5555);
    ExpectSame(p, m->payload);
    types.insert(p.index());
  }
  EXPECT_EQ(types.size(), std::variant_size_v<Payload>);
}

TEST(ProtocolMessages, VersionMismatchIsAClearRefusal) {
  Header h;
  h.version = 7;
  uint8_t bytes[kHeaderSize];
  EncodeHeader(h, bytes);
  auto r = DecodeHeader(bytes, kHeaderSize);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kUnsupportedVersion);
  EXPECT_NE(r.status().message().find("peer speaks protocol version 7, this build speaks 1"), std::string::npos)
      << r.status().message();
  FrameParser parser;
  EXPECT_EQ(parser.Feed(bytes, kHeaderSize).code(), StatusCode::kUnsupportedVersion);
  // The refusal a server sends back reads with any version's Refuse layout.
  Refuse refuse{RefuseReason::kUnsupportedVersion, 1, 1, r.status().message()};
  auto m = DecodeMessage(EncodeMessage({}, refuse));
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(std::get<Refuse>(m->payload).message, r.status().message());
}

TEST(ProtocolMessages, HeaderViolations) {
  Header h;
  uint8_t bytes[kHeaderSize];
  EncodeHeader(h, bytes);
  auto with = [&](size_t at, uint8_t v) {
    uint8_t b[kHeaderSize];
    std::memcpy(b, bytes, kHeaderSize);
    b[at] = v;
    return DecodeHeader(b, kHeaderSize).status();
  };
  EXPECT_NE(with(0, 'X').message().find("magic"), std::string::npos);
  EXPECT_NE(with(6, 99).message().find("unknown message type 99"), std::string::npos);
  EXPECT_NE(with(8, 0x80).message().find("flags"), std::string::npos);
  EXPECT_NE(with(10, 1).message().find("reserved"), std::string::npos);
  EXPECT_NE(with(31, 0xFF).message().find("payload_length"), std::string::npos);
  EXPECT_FALSE(DecodeHeader(bytes, kHeaderSize - 1).ok());
}

TEST(ProtocolMessages, FrameParserHandlesSplitAndMergedReads) {
  const auto samples = test::SamplePayloads();
  std::vector<uint8_t> stream;
  for (size_t i = 0; i < samples.size(); ++i) {
    Header h;
    h.sequence = static_cast<uint32_t>(i);
    const auto m = EncodeMessage(h, samples[i]);
    stream.insert(stream.end(), m.begin(), m.end());
  }
  for (size_t chunk : {size_t{1}, size_t{3}, size_t{31}, size_t{32}, size_t{33}, size_t{1000}, stream.size()}) {
    FrameParser parser;
    MessageAssembler assembler;
    size_t got = 0;
    for (size_t off = 0; off < stream.size(); off += chunk) {
      ASSERT_TRUE(parser.Feed(stream.data() + off, std::min(chunk, stream.size() - off)).ok());
      Frame f;
      while (parser.Next(&f)) {
        bool complete = false;
        Message m;
        ASSERT_TRUE(assembler.Add(std::move(f), &complete, &m).ok());
        ASSERT_TRUE(complete);
        EXPECT_EQ(m.header.sequence, got);
        ExpectSame(samples[got], m.payload);
        ++got;
      }
    }
    EXPECT_EQ(got, samples.size()) << "chunk " << chunk;
    EXPECT_EQ(parser.buffered(), 0u);
  }
}

TEST(ProtocolMessages, FragmentsInterleaveWithAudio) {
  MeshFrame big;
  big.frame_index = 5;
  big.data.resize(100000);
  for (size_t i = 0; i < big.data.size(); ++i) big.data[i] = static_cast<uint8_t>(i * 7);
  Header vh;
  vh.stream_id = 1;
  vh.sequence = 5;
  const auto frags = EncodeFragmented(vh, big, 16384);
  ASSERT_EQ(frags.size(), 7u);
  AudioPose audio = std::get<AudioPose>(test::SamplePayloads()[6]);
  std::vector<uint8_t> stream;
  for (size_t i = 0; i < frags.size(); ++i) {
    stream.insert(stream.end(), frags[i].begin(), frags[i].end());
    Header ah;
    ah.stream_id = 2;
    ah.sequence = static_cast<uint32_t>(i);
    const auto a = EncodeMessage(ah, audio);
    stream.insert(stream.end(), a.begin(), a.end());
  }
  FrameParser parser;
  MessageAssembler assembler;
  ASSERT_TRUE(parser.Feed(stream.data(), stream.size()).ok());
  Frame f;
  int audio_count = 0, mesh_count = 0;
  while (parser.Next(&f)) {
    bool complete = false;
    Message m;
    ASSERT_TRUE(assembler.Add(std::move(f), &complete, &m).ok());
    if (!complete) continue;
    if (m.header.type == MessageType::kAudioPose) {
      ++audio_count;
    } else {
      // Six audio frames went out between the seven fragments: none waited for the whole video frame.
      EXPECT_EQ(audio_count, 6);
      ++mesh_count;
      EXPECT_TRUE(std::get<MeshFrame>(m.payload) == big);
    }
  }
  EXPECT_EQ(audio_count, 7);
  EXPECT_EQ(mesh_count, 1);
}

TEST(ProtocolMessages, FragmentViolations) {
  MeshFrame big;
  big.data.resize(5000);
  Header h;
  h.sequence = 1;
  auto frags = EncodeFragmented(h, big, 1000);
  FrameParser parser;
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(parser.Feed(frags[i].data(), frags[i].size()).ok());
  h.sequence = 2;  // a different message interrupts on the same stream and type
  auto other = EncodeFragmented(h, big, 1000);
  ASSERT_TRUE(parser.Feed(other[0].data(), other[0].size()).ok());
  MessageAssembler assembler;
  Frame f;
  bool complete = false;
  Message m;
  ASSERT_TRUE(parser.Next(&f));
  ASSERT_TRUE(assembler.Add(std::move(f), &complete, &m).ok());
  ASSERT_TRUE(parser.Next(&f));
  ASSERT_TRUE(assembler.Add(std::move(f), &complete, &m).ok());
  ASSERT_TRUE(parser.Next(&f));
  EXPECT_EQ(assembler.Add(std::move(f), &complete, &m).code(), StatusCode::kDataLoss);

  // A reassembled message over the limit.
  Limits small;
  small.max_message_bytes = 2500;
  MessageAssembler limited(small);
  Status s;
  for (auto& fr : frags) {
    auto hd = DecodeHeader(fr.data(), kHeaderSize);
    ASSERT_TRUE(hd.ok());
    s = limited.Add(Frame{*hd, std::vector<uint8_t>(fr.begin() + kHeaderSize, fr.end())}, &complete, &m);
    if (!s.ok()) break;
  }
  EXPECT_NE(s.message().find("exceeds limit"), std::string::npos) << s.ToString();
}

TEST(ProtocolMessages, ParserStaysFailedAfterAnError) {
  FrameParser parser;
  const uint8_t junk[kHeaderSize] = {'G', 'E', 'T', ' '};
  EXPECT_FALSE(parser.Feed(junk, sizeof(junk)).ok());
  const auto ok = EncodeMessage({}, Ping{});
  EXPECT_FALSE(parser.Feed(ok.data(), ok.size()).ok());
  Frame f;
  EXPECT_FALSE(parser.Next(&f));
}

TEST(ProtocolMessages, SemanticChecks) {
  ClientPose cp;
  cp.rotation = {2, 0, 0, 0};
  EXPECT_NE(DecodeMessage(EncodeMessage({}, cp)).status().message().find("quaternion"), std::string::npos);
  AudioPose pcm;
  pcm.codec = AudioCodec::kPcm16;
  pcm.audio.resize(100);
  EXPECT_NE(DecodeMessage(EncodeMessage({}, pcm)).status().message().find("PCM frame"), std::string::npos);
  auto bytes = EncodeMessage({}, Ping{});
  bytes.push_back(0);  // trailing byte, and a length that no longer matches
  EXPECT_FALSE(DecodeMessage(bytes).ok());
  auto p = EncodePayload(Ping{});
  p.push_back(0);
  EXPECT_NE(DecodePayload(MessageType::kPing, p).status().message().find("trailing"), std::string::npos);
  const Control loop{ControlCommand::kSetLoop, 0, 1, 1.0f};
  auto decoded = DecodeMessage(EncodeMessage({}, loop));
  ASSERT_TRUE(decoded.ok()) << decoded.status().message();
  EXPECT_EQ(std::get<Control>(decoded->payload), loop);
  EXPECT_NE(DecodeMessage(EncodeMessage({}, Control{ControlCommand::kSetLoop, 0, 2, 1.0f}))
                .status().message().find("set loop takes 0 or 1"),
            std::string::npos);
}

TEST(ByteIo, HalfFloatConversion) {
  for (float f : {0.0f, -0.0f, 1.0f, -2.5f, 65504.0f, 6.1035156e-05f, 5.9604645e-08f, 1.2345f, 1000.1f}) {
    const float g = HalfToFloat(FloatToHalf(f));
    EXPECT_NEAR(g, f, std::abs(f) * 1e-3f + 1e-9f) << f;
  }
  EXPECT_TRUE(std::isinf(HalfToFloat(FloatToHalf(1e6f))));
  EXPECT_EQ(FloatToHalf(1.0f), 0x3C00);
  EXPECT_EQ(FloatToHalf(-2.0f), 0xC000);
  for (uint32_t h = 0; h < 0x7C00; ++h) EXPECT_EQ(FloatToHalf(HalfToFloat(static_cast<uint16_t>(h))), h);
}

TEST(ByteIo, ReaderNamesTheField) {
  const uint8_t b[3] = {1, 2, 3};
  ByteReader r(b, 3);
  uint32_t v = 0;
  const Status s = r.U32("thing.count", &v);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_EQ(s.message(), "thing.count: needs 4 bytes, 3 remain");
  EXPECT_NE(r.CheckCount("mesh.num_triangles", 1000000, 12).message().find("mesh.num_triangles"), std::string::npos);
  EXPECT_FALSE(r.CheckCount("x", UINT64_MAX, 16).ok());  // no overflow
}

}  // namespace
}  // namespace holo::protocol
