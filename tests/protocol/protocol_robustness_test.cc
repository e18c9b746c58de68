// Untrusted bytes: every truncated prefix, random bit flips, absurd counts.
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <random>

#include "protocol/byte_io.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/sample_messages.h"

namespace holo::protocol {
namespace {

// A copy in its own heap block of exactly `n` bytes, so ASan sees any overrun.
std::unique_ptr<uint8_t[]> Fresh(const std::vector<uint8_t>& src, size_t n) {
  std::unique_ptr<uint8_t[]> p(new uint8_t[n == 0 ? 1 : n]);
  if (n) std::memcpy(p.get(), src.data(), n);
  return p;
}

std::vector<std::vector<uint8_t>> SampleMessages() {
  std::vector<std::vector<uint8_t>> out;
  uint32_t seq = 0;
  for (const Payload& p : test::SamplePayloads()) {
    Header h;
    h.sequence = seq++;
    out.push_back(EncodeMessage(h, p));
  }
  return out;
}

std::vector<std::vector<uint8_t>> SampleBlobs() {
  std::vector<std::vector<uint8_t>> out;
  for (auto& [name, bytes] : test::SampleCodecInputs(5, 8, 20, 14)) out.push_back(std::move(bytes));
  return out;
}

TEST(ProtocolRobustness, EveryTruncatedMessageIsAnError) {
  for (const auto& m : SampleMessages()) {
    for (size_t n = 0; n < m.size(); ++n) {
      auto buf = Fresh(m, n);
      EXPECT_FALSE(DecodeMessage({buf.get(), n}).ok()) << "prefix " << n << " of " << m.size();
      if (n >= kHeaderSize) {  // the payload alone, truncated
        auto h = DecodeHeader(buf.get(), kHeaderSize);
        ASSERT_TRUE(h.ok());
        EXPECT_FALSE(DecodePayload(h->type, {buf.get() + kHeaderSize, n - kHeaderSize}).ok());
      }
      // A stream cut here yields no message and no error, only buffered bytes.
      FrameParser parser;
      EXPECT_TRUE(parser.Feed(buf.get(), n).ok());
      Frame f;
      EXPECT_FALSE(parser.Next(&f));
    }
  }
}

TEST(ProtocolRobustness, EveryTruncatedCodecBlobIsAnError) {
  for (const auto& blob : SampleBlobs()) {
    const std::vector<uint8_t> body(blob.begin() + 1, blob.end());
    for (size_t n = 0; n < body.size(); ++n) {
      auto buf = Fresh(body, n);
      if (blob[0] == static_cast<uint8_t>(FuzzTarget::kGeometry)) {
        Mesh mesh;
        EXPECT_FALSE(DecodeGeometry({buf.get(), n}, &mesh).ok()) << "geometry prefix " << n;
        EXPECT_TRUE(mesh.empty());
      } else {
        ImageRgb8 im;
        ImageGray8 mask;
        EXPECT_FALSE(DecodeColor({buf.get(), n}, &im, &mask).ok()) << "color prefix " << n;
      }
    }
    EXPECT_EQ(FuzzDecoders(blob.data(), blob.size()), 1);  // and the whole blob decodes
  }
}

TEST(ProtocolRobustness, RandomBitFlipsNeverCrashOrHang) {
  std::vector<std::vector<uint8_t>> seeds;
  std::vector<uint8_t> stream;
  for (const auto& m : SampleMessages()) {
    seeds.push_back(FuzzInput(FuzzTarget::kMessage, m));
    stream.insert(stream.end(), m.begin(), m.end());
  }
  seeds.push_back(FuzzInput(FuzzTarget::kStream, stream));
  for (auto& b : SampleBlobs()) seeds.push_back(b);
  std::mt19937 rng(12345);
  const auto start = std::chrono::steady_clock::now();
  int decoded = 0;
  const int kMutations = 100000;
  for (int i = 0; i < kMutations; ++i) {
    std::vector<uint8_t> m = seeds[i % seeds.size()];
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < flips; ++k) {
      const size_t at = 1 + rng() % (m.size() - 1);  // keep the target byte
      m[at] ^= static_cast<uint8_t>(1u << (rng() % 8));
    }
    auto buf = Fresh(m, m.size());
    decoded += FuzzDecoders(buf.get(), m.size());
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Some flips land in payload data (audio bytes, JPEG entropy data) and still decode.
  EXPECT_GT(decoded, 0);
  EXPECT_LT(s, 600.0) << "mutated inputs took too long: a decoder may loop";
  std::printf("%d mutations in %.1f s, %d still decoded\n", kMutations, s, decoded);
}

TEST(ProtocolRobustness, AbsurdCountsAreRefusedBeforeAllocation) {
  // Geometry claiming the limit's vertex count with a 20-byte body.
  for (uint8_t codec : {1, 2}) {
    std::vector<uint8_t> b;
    ByteWriter w(&b);
    w.U8(codec);
    w.U8(3);
    w.U16(0);
    w.U32(2u << 20);
    w.U32(4u << 20);
    w.U32(0);
    w.U32(0);
    Mesh mesh;
    const Status s = DecodeGeometry(b, &mesh);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss);
    EXPECT_TRUE(s.message().find("num_") != std::string::npos || s.message().find("g1.") != std::string::npos)
        << s.message();
    b[4] = 0xFF;  // over the limit
    b[7] = 0xFF;
    EXPECT_NE(DecodeGeometry(b, &mesh).message().find("exceeds limit"), std::string::npos);
  }
  // Rig with 60000 pods, stats with 65535 entries, a 4 GB blob.
  {
    std::vector<uint8_t> p;
    ByteWriter w(&p);
    w.String16("r");
    w.U16(60000);
    EXPECT_NE(DecodePayload(MessageType::kRig, p).status().message().find("rig.num_pods"), std::string::npos);
    Limits many;
    many.max_pods = 64;
    p.clear();
    w.String16("r");
    w.U16(64);
    EXPECT_NE(DecodePayload(MessageType::kRig, p, many).status().message().find("exceeds the"), std::string::npos);
  }
  {
    std::vector<uint8_t> p;
    ByteWriter w(&p);
    w.U16(65535);
    EXPECT_NE(DecodePayload(MessageType::kStats, p).status().message().find("stats.count"), std::string::npos);
    p.clear();
    w.I64(1);
    w.U8(2);
    w.U32(0xFFFFFFFFu);
    EXPECT_NE(DecodePayload(MessageType::kMeshFrame, p).status().message().find("mesh_frame.data"), std::string::npos);
  }
  // A frame header announcing 4 GB is refused by the parser before any buffer grows.
  {
    Header h;
    h.payload_length = 0xFFFFFFF0u;
    uint8_t b[kHeaderSize];
    EncodeHeader(h, b);
    FrameParser parser;
    EXPECT_NE(parser.Feed(b, kHeaderSize).message().find("payload_length"), std::string::npos);
  }
  // A colour blob claiming a huge image.
  {
    std::vector<uint8_t> b;
    ByteWriter w(&b);
    w.U8(1);
    w.U8(0);
    w.U16(8192);
    w.U16(8192);
    w.U32(10);
    for (int i = 0; i < 10; ++i) w.U8(0);
    ImageRgb8 im;
    ImageGray8 mask;
    EXPECT_EQ(DecodeColor(b, &im, &mask).code(), StatusCode::kDataLoss);
    b[3] = 0x08;  // 2048 x 2048 passes the size limits: then LZ4's ratio bound refuses it
    b[5] = 0x08;
    EXPECT_NE(DecodeColor(b, &im, &mask).message().find("cannot come from"), std::string::npos);
  }
}

}  // namespace
}  // namespace holo::protocol
