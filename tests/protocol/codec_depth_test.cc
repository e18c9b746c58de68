// D1 depth codec (protocol/depth_codec.h): lossless round trip, and a clear
// error for every truncation, bit flip and lie in the header. (D2:
// codec_depth_d2_test.cc.)
#include <gtest/gtest.h>

#include <random>

#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "protocol/fuzz_decoders.h"

namespace holo::protocol {
namespace {

ImageDepth16 SampleDepth(int w, int h, uint32_t seed) {
  std::mt19937 rng(seed);
  ImageDepth16 d(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool hole = rng() % 17 == 0;
      d.at(x, y) = hole ? 0 : static_cast<uint16_t>(1500 + 2 * x - y + static_cast<int>(rng() % 9));
    }
  d.at(0, 0) = 65535;  // extremes survive the mod-2^16 deltas
  if (w > 1) d.at(1, 0) = 0;
  return d;
}

TEST(DepthCodec, RoundTripIsExact) {
  for (auto [w, h] : {std::pair{1, 1}, std::pair{7, 3}, std::pair{320, 240}}) {
    const ImageDepth16 d = SampleDepth(w, h, 5);
    std::vector<uint8_t> blob;
    ASSERT_TRUE(EncodeDepth(d, {}, &blob).ok());
    ImageDepth16 out;
    ASSERT_TRUE(DecodeDepth(blob, &out).ok());
    EXPECT_EQ(out, d) << w << "x" << h;
    int pw = 0, ph = 0;
    ASSERT_TRUE(PeekDepthSize(blob, &pw, &ph).ok());
    EXPECT_EQ(pw, w);
    EXPECT_EQ(ph, h);
  }
}

TEST(DepthCodec, SmoothDepthCompresses) {
  ImageDepth16 d(320, 240);
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < 320; ++x) d.at(x, y) = static_cast<uint16_t>(2000 + x + (y / 8));
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeDepth(d, {}, &blob).ok());
  EXPECT_LT(blob.size(), d.num_pixels() * 2 / 20);
}

TEST(DepthCodec, EveryPrefixIsAnError) {
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeDepth(SampleDepth(16, 9, 1), {}, &blob).ok());
  for (size_t n = 0; n < blob.size(); ++n) {
    std::vector<uint8_t> prefix(blob.begin(), blob.begin() + static_cast<ptrdiff_t>(n));  // fresh buffer for ASan
    ImageDepth16 out;
    const Status s = DecodeDepth(prefix, &out);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << n;
  }
  std::vector<uint8_t> longer = blob;
  longer.push_back(0);
  ImageDepth16 out;
  EXPECT_EQ(DecodeDepth(longer, &out).code(), StatusCode::kDataLoss);
}

TEST(DepthCodec, BitFlipsNeverCrashAndKeepSizes) {
  std::vector<uint8_t> blob;
  const ImageDepth16 d = SampleDepth(16, 9, 2);
  ASSERT_TRUE(EncodeDepth(d, {}, &blob).ok());
  for (size_t i = 0; i < blob.size(); ++i)
    for (int bit = 0; bit < 8; ++bit) {
      std::vector<uint8_t> b = blob;
      b[i] ^= static_cast<uint8_t>(1u << bit);
      ImageDepth16 out;
      if (DecodeDepth(b, &out).ok()) {
        int w = 0, h = 0;
        ASSERT_TRUE(PeekDepthSize(b, &w, &h).ok());
        EXPECT_EQ(out.width(), w);
        EXPECT_EQ(out.height(), h);
      }
    }
}

TEST(DepthCodec, HeaderLiesAreRefusedBeforeAllocation) {
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeDepth(SampleDepth(16, 9, 3), {}, &blob).ok());
  // Another size than the zstd frame declares.
  std::vector<uint8_t> b = blob;
  b[1] = 17;
  ImageDepth16 out;
  Status s = DecodeDepth(b, &out);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("depth.zstd"), std::string::npos) << s.message();
  // A size over the limits.
  Limits small;
  small.max_image_dim = 8;
  s = DecodeDepth(blob, &out, small);
  EXPECT_NE(s.message().find("outside 1..8"), std::string::npos) << s.message();
  // Unknown codec.
  b = blob;
  b[0] = 3;
  s = DecodeDepth(b, &out);
  EXPECT_NE(s.message().find("unknown depth codec 3"), std::string::npos) << s.message();
}

TEST(DepthCodec, PodFrameFuzzEntryDecodesAValidFrame) {
  PodFrame f;
  f.pod_id = 2;
  ASSERT_TRUE(EncodeDepth(SampleDepth(8, 8, 4), {}, &f.depth).ok());
  ImageRgb8 im(8, 8, 90);
  ImageGray8 mask;
  ColorEncodeOptions co;
  ASSERT_TRUE(EncodeColor(im, mask, co, &f.color).ok());
  const std::vector<uint8_t> bytes = EncodePayload(f);
  EXPECT_EQ(FuzzPodFrame(bytes), 3);
  // The message decoder refuses what the blob decoders would never see.
  std::vector<uint8_t> bad = bytes;
  bad[2 + 8 + 8] = 9;  // depth codec
  EXPECT_EQ(FuzzPodFrame(bad), 0);
}

}  // namespace
}  // namespace holo::protocol
