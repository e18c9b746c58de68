#include <gtest/gtest.h>

#include <cmath>

#include "protocol/color_codec.h"
#include "protocol/test_meshes.h"

namespace holo::protocol {
namespace {

double Psnr(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8& mask) {
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      if (!mask.at(x, y)) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(a.at(x, y, c)) - b.at(x, y, c);
        se += d * d;
        ++n;
      }
    }
  return se == 0 ? 99 : 10 * std::log10(255.0 * 255.0 * n / se);
}

TEST(ColorCodec, C0IsLosslessOnTheForeground) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(64, 48, &im, &mask);
  im.at(30, 25, 0) = im.at(30, 25, 1) = im.at(30, 25, 2) = 0;  // pure black inside the mask
  ASSERT_TRUE(mask.at(30, 25));
  ColorEncodeOptions o;
  o.codec = ColorCodec::kC0;
  std::vector<uint8_t> blob;
  ASSERT_TRUE(EncodeColor(im, mask, o, &blob).ok());
  ImageRgb8 out;
  ImageGray8 out_mask;
  ASSERT_TRUE(DecodeColor(blob, &out, &out_mask).ok());
  EXPECT_TRUE(out_mask == mask);
  int differing = 0;
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x)
      for (int c = 0; c < 3; ++c) {
        if (mask.at(x, y)) differing += out.at(x, y, c) != im.at(x, y, c);
        else EXPECT_EQ(out.at(x, y, c), 0);
      }
  EXPECT_EQ(differing, 1);  // only the black pixel, nudged to (0, 0, 1)
}

TEST(ColorCodec, C1KeepsTheMaskExactAndTheColorClose) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(160, 120, &im, &mask);
  for (bool c420 : {true, false}) {
    ColorEncodeOptions o;
    o.chroma_420 = c420;
    std::vector<uint8_t> blob;
    ASSERT_TRUE(EncodeColor(im, mask, o, &blob).ok());
    ImageRgb8 out;
    ImageGray8 out_mask;
    const Status s = DecodeColor(blob, &out, &out_mask);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(out_mask == mask);
    EXPECT_GT(Psnr(im, out, mask), 33.0);
    EXPECT_LT(blob.size(), im.storage().size() / 4);
  }
}

TEST(ColorCodec, EmptyAndFullMasks) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(32, 20, &im, &mask);
  for (auto codec : {ColorCodec::kC0, ColorCodec::kC1}) {
    ColorEncodeOptions o;
    o.codec = codec;
    ImageGray8 none(32, 20, 0);
    std::vector<uint8_t> blob;
    ASSERT_TRUE(EncodeColor(im, none, o, &blob).ok());
    ImageRgb8 out;
    ImageGray8 out_mask;
    ASSERT_TRUE(DecodeColor(blob, &out, &out_mask).ok());
    EXPECT_TRUE(out_mask == none);
    blob.clear();
    ASSERT_TRUE(EncodeColor(im, ImageGray8(), o, &blob).ok());  // no mask: all foreground
    ASSERT_TRUE(DecodeColor(blob, &out, &out_mask).ok());
    EXPECT_TRUE(out_mask == ImageGray8(32, 20, 255));
  }
}

TEST(ColorCodec, ReservedH264AndBadInput) {
  std::vector<uint8_t> blob = {3, 0, 16, 0, 16, 0};
  ImageRgb8 out;
  ImageGray8 mask;
  EXPECT_EQ(DecodeColor(blob, &out, &mask).code(), StatusCode::kUnsupportedVersion);
  ColorEncodeOptions o;
  o.codec = ColorCodec::kH264;
  ImageRgb8 im(8, 8);
  EXPECT_EQ(EncodeColor(im, {}, o, &blob).code(), StatusCode::kInvalidArgument);
  o = {};
  EXPECT_EQ(EncodeColor(im, ImageGray8(4, 4), o, &blob).code(), StatusCode::kInvalidArgument);
  o.jpeg_quality = 0;
  EXPECT_EQ(EncodeColor(im, {}, o, &blob).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace holo::protocol
