#include "common/image_io.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "test_util.h"

namespace holo {
namespace {

ImageRgb8 Pattern(int w, int h) {
  ImageRgb8 im(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      im.at(x, y, 0) = static_cast<uint8_t>(x * 7 + y);
      im.at(x, y, 1) = static_cast<uint8_t>(y * 13);
      im.at(x, y, 2) = static_cast<uint8_t>(x ^ y);
    }
  return im;
}

bool Contains(const Status& s, const std::string& needle) { return s.message().find(needle) != std::string::npos; }

TEST(ImageIo, RgbPngRoundTripIsExactAndKeepsChannelOrder) {
  const std::string dir = test::MakeTempDir("image_io");
  const ImageRgb8 im = Pattern(37, 21);
  ASSERT_TRUE(WriteImageRgb8(dir + "/a.png", im).ok());
  auto back = ReadImageRgb8(dir + "/a.png");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, im);

  // A pure red image must read back red (catches a missing BGR<->RGB swap on one side).
  ImageRgb8 red(4, 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) red.at(x, y, 0) = 255;
  ASSERT_TRUE(WriteImageRgb8(dir + "/red.PNG", red).ok());
  auto red_back = ReadImageRgb8(dir + "/red.PNG");
  ASSERT_TRUE(red_back.ok());
  EXPECT_EQ(red_back->at(1, 1, 0), 255);
  EXPECT_EQ(red_back->at(1, 1, 2), 0);
}

TEST(ImageIo, JpegRoundTripIsCloseAndQualityMatters) {
  const std::string dir = test::MakeTempDir("image_io");
  ImageRgb8 im(64, 48);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      im.at(x, y, 0) = static_cast<uint8_t>(x * 4);
      im.at(x, y, 1) = static_cast<uint8_t>(y * 5);
      im.at(x, y, 2) = 128;
    }
  ImageWriteOptions hi, lo;
  hi.jpeg_quality = 98;
  lo.jpeg_quality = 5;
  ASSERT_TRUE(WriteImageRgb8(dir + "/hi.jpg", im, hi).ok());
  ASSERT_TRUE(WriteImageRgb8(dir + "/lo.jpeg", im, lo).ok());
  auto a = ReadImageRgb8(dir + "/hi.jpg");
  auto b = ReadImageRgb8(dir + "/lo.jpeg");
  ASSERT_TRUE(a.ok() && b.ok());
  double err_hi = 0, err_lo = 0;
  for (size_t i = 0; i < im.storage().size(); ++i) {
    err_hi += std::abs(int(a->storage()[i]) - int(im.storage()[i]));
    err_lo += std::abs(int(b->storage()[i]) - int(im.storage()[i]));
  }
  err_hi /= static_cast<double>(im.storage().size());
  err_lo /= static_cast<double>(im.storage().size());
  EXPECT_LT(err_hi, 2.0);
  EXPECT_GT(err_lo, err_hi);
  EXPECT_GT(std::filesystem::file_size(dir + "/hi.jpg"), std::filesystem::file_size(dir + "/lo.jpeg"));
}

TEST(ImageIo, DepthAndMaskRoundTripExactly) {
  const std::string dir = test::MakeTempDir("image_io");
  ImageDepth16 d(33, 17);
  for (size_t i = 0; i < d.storage().size(); ++i) d.storage()[i] = static_cast<uint16_t>(i * 977 % 65536);
  d.at(0, 0) = 65535;
  d.at(1, 0) = 0;
  ASSERT_TRUE(WriteDepth16(dir + "/d.png", d).ok());
  auto db = ReadDepth16(dir + "/d.png");
  ASSERT_TRUE(db.ok()) << db.status().ToString();
  EXPECT_EQ(*db, d);

  ImageGray8 m(33, 17);
  for (size_t i = 0; i < m.storage().size(); ++i) m.storage()[i] = (i % 3) ? 255 : 0;
  ASSERT_TRUE(WriteMask8(dir + "/m.png", m).ok());
  auto mb = ReadMask8(dir + "/m.png");
  ASSERT_TRUE(mb.ok());
  EXPECT_EQ(*mb, m);

  // Reading into an existing image replaces size and content.
  ImageDepth16 reused(5, 5, 7);
  ASSERT_TRUE(ReadDepth16(dir + "/d.png", &reused).ok());
  EXPECT_EQ(reused, d);
}

TEST(ImageIo, ReadsRealSixteenBitFixture) {
  auto d = ReadDepth16(test::TestDataPath("person/person_depth_mm.png"));
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  EXPECT_EQ(d->width(), 640);
  EXPECT_EQ(d->height(), 480);
  size_t valid = 0;
  uint16_t lo = 65535, hi = 0;
  for (uint16_t v : d->storage())
    if (v) {
      ++valid;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  // SOURCE.txt: 79% valid, 0.61-3.78 m.
  EXPECT_NEAR(static_cast<double>(valid) / d->num_pixels(), 0.79, 0.01);
  EXPECT_NEAR(lo, 610, 10);
  EXPECT_NEAR(hi, 3780, 10);
}

TEST(ImageIo, ErrorsNameTheFileAndTheProblem) {
  const std::string dir = test::MakeTempDir("image_io");
  // Missing file.
  auto missing = ReadImageRgb8(dir + "/nope.png");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(missing.status(), dir + "/nope.png"));

  // 8-bit PNG read as depth.
  ASSERT_TRUE(WriteMask8(dir + "/eight.png", ImageGray8(4, 4, 9)).ok());
  auto eight = ReadDepth16(dir + "/eight.png");
  ASSERT_FALSE(eight.ok());
  EXPECT_EQ(eight.status().message(), dir + "/eight.png: depth must be a 16-bit single-channel PNG, got 8-bit");

  // RGB PNG read as depth or as mask.
  ASSERT_TRUE(WriteImageRgb8(dir + "/rgb.png", Pattern(4, 4)).ok());
  auto rgb_depth = ReadDepth16(dir + "/rgb.png");
  ASSERT_FALSE(rgb_depth.ok());
  EXPECT_TRUE(Contains(rgb_depth.status(), "got 8-bit 3-channel")) << rgb_depth.status().message();
  auto rgb_mask = ReadMask8(dir + "/rgb.png");
  ASSERT_FALSE(rgb_mask.ok());
  EXPECT_TRUE(Contains(rgb_mask.status(), "mask must be an 8-bit single-channel PNG"));

  // 16-bit PNG read as color.
  ASSERT_TRUE(WriteDepth16(dir + "/sixteen.png", ImageDepth16(4, 4, 1000)).ok());
  auto sixteen = ReadImageRgb8(dir + "/sixteen.png");
  ASSERT_FALSE(sixteen.ok());
  EXPECT_TRUE(Contains(sixteen.status(), dir + "/sixteen.png: color must be an 8-bit image, got 16-bit"));

  // JPEG read as depth.
  ASSERT_TRUE(WriteImageRgb8(dir + "/c.jpg", Pattern(8, 8)).ok());
  auto jpeg_depth = ReadDepth16(dir + "/c.jpg");
  ASSERT_FALSE(jpeg_depth.ok());
  EXPECT_TRUE(Contains(jpeg_depth.status(), "non-PNG"));

  // Garbage, empty and truncated files.
  ASSERT_TRUE(WriteStringToFile(dir + "/garbage.png", "this is not an image").ok());
  auto garbage = ReadImageRgb8(dir + "/garbage.png");
  ASSERT_FALSE(garbage.ok());
  EXPECT_EQ(garbage.status().code(), StatusCode::kDataLoss);
  EXPECT_TRUE(Contains(garbage.status(), dir + "/garbage.png: cannot decode"));
  ASSERT_TRUE(WriteStringToFile(dir + "/empty.png", "").ok());
  EXPECT_FALSE(ReadDepth16(dir + "/empty.png").ok());

  // Unsupported extensions and bad options.
  EXPECT_EQ(WriteImageRgb8(dir + "/a.bmp", Pattern(2, 2)).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteDepth16(dir + "/a.jpg", ImageDepth16(2, 2)).code(), StatusCode::kInvalidArgument);
  ImageWriteOptions bad;
  bad.jpeg_quality = 0;
  const Status q = WriteImageRgb8(dir + "/q.jpg", Pattern(2, 2), bad);
  EXPECT_TRUE(Contains(q, "jpeg_quality must be in 1..100, got 0")) << q.message();
  EXPECT_FALSE(WriteImageRgb8(dir + "/empty_image.png", ImageRgb8()).ok());
}

TEST(ImageIo, HugePngHeaderIsRefusedBeforeDecoding) {
  const std::string dir = test::MakeTempDir("image_io");
  ASSERT_TRUE(WriteDepth16(dir + "/d.png", ImageDepth16(4, 4, 1)).ok());
  auto bytes = ReadFileToString(dir + "/d.png");
  ASSERT_TRUE(bytes.ok());
  std::vector<uint8_t> b(bytes->begin(), bytes->end());
  // IHDR width and height (big-endian at offsets 16 and 20) := 100000 x 100000.
  for (int off : {16, 20}) {
    b[off] = 0x00;
    b[off + 1] = 0x01;
    b[off + 2] = 0x86;
    b[off + 3] = 0xA0;
  }
  ImageDepth16 out;
  const Status s = DecodeDepth16(b.data(), b.size(), "huge.png", &out);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_TRUE(Contains(s, "huge.png: PNG header says 100000x100000")) << s.message();
}

TEST(ImageIo, EveryTruncatedPngPrefixIsAnErrorNotACrash) {
  const std::string dir = test::MakeTempDir("image_io");
  ImageDepth16 d(9, 7);
  for (size_t i = 0; i < d.storage().size(); ++i) d.storage()[i] = static_cast<uint16_t>(i * 311);
  ASSERT_TRUE(WriteDepth16(dir + "/d.png", d).ok());
  auto bytes = ReadFileToString(dir + "/d.png");
  ASSERT_TRUE(bytes.ok());
  for (size_t n = 0; n < bytes->size(); ++n) {
    // A fresh buffer of exactly n bytes so that ASan sees any overrun.
    std::vector<uint8_t> prefix(bytes->begin(), bytes->begin() + static_cast<std::ptrdiff_t>(n));
    ImageDepth16 out;
    const Status s = DecodeDepth16(prefix.data(), prefix.size(), "prefix", &out);
    // libpng may tolerate a missing IEND chunk; everything shorter must fail.
    if (s.ok()) {
      EXPECT_EQ(out, d) << "prefix of " << n << " bytes";
    }
  }
}

}  // namespace
}  // namespace holo
