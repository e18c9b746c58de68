#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <thread>

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

// A receiver decodes each pod's stream into the same images frame after
// frame: whatever they held before (another box, garbage, a failed decode),
// the result is the same as a decode into fresh images.
TEST(ColorCodec, DecodeIntoReusedImagesMatchesFreshImages) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(160, 120, &im, &mask);
  ImageGray8 moved(160, 120), small(160, 120), empty(160, 120);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      moved.at(x, y) = x >= 37 && y >= 21 ? mask.at(x - 37, y - 21) : 0;
      small.at(x, y) = (x - 20) * (x - 20) + (y - 15) * (y - 15) < 49 ? 255 : 0;
    }
  ColorEncodeOptions o;
  std::vector<std::vector<uint8_t>> blobs;
  for (const ImageGray8* m : {&mask, &moved, &small, &empty, &mask}) {
    blobs.emplace_back();
    ASSERT_TRUE(EncodeColor(im, *m, o, &blobs.back()).ok());
  }
  ImageRgb8 out(160, 120, 77);
  ImageGray8 out_mask(160, 120, 9);
  for (size_t i = 0; i < blobs.size(); ++i) {
    ImageRgb8 fresh;
    ImageGray8 fresh_mask;
    ASSERT_TRUE(DecodeColor(blobs[i], &fresh, &fresh_mask).ok());
    ASSERT_TRUE(DecodeColor(blobs[i], &out, &out_mask).ok()) << i;
    EXPECT_TRUE(out == fresh) << "blob " << i;
    EXPECT_TRUE(out_mask == fresh_mask) << "blob " << i;
    // A truncated blob fails; the next good one is still decoded exactly.
    std::vector<uint8_t> cut(blobs[i].begin(), blobs[i].begin() + static_cast<long>(blobs[i].size() * 2 / 3));
    EXPECT_FALSE(DecodeColor(cut, &out, &out_mask).ok()) << i;
  }
  ImageRgb8 fresh;
  ImageGray8 fresh_mask;
  ASSERT_TRUE(DecodeColor(blobs[1], &fresh, &fresh_mask).ok());
  ASSERT_TRUE(DecodeColor(blobs[1], &out, &out_mask).ok());
  EXPECT_TRUE(out == fresh);
  EXPECT_TRUE(out_mask == fresh_mask);
}

// A stream decoder clears only the boxes it wrote: over boxes that move,
// shrink, vanish, a C0 image and a failed blob, each result equals a decode
// into fresh images.
TEST(ColorCodec, StreamDecoderMatchesFreshDecodes) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(160, 120, &im, &mask);
  ImageGray8 moved(160, 120), small(160, 120), empty(160, 120), corner(160, 120);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      moved.at(x, y) = x >= 37 && y >= 21 ? mask.at(x - 37, y - 21) : 0;
      small.at(x, y) = (x - 20) * (x - 20) + (y - 15) * (y - 15) < 49 ? 255 : 0;
      corner.at(x, y) = (x > 150 || y > 110) ? 255 : 0;
    }
  ColorEncodeOptions c1, c0;
  c0.codec = ColorCodec::kC0;
  std::vector<std::vector<uint8_t>> blobs;
  auto add = [&](const ImageGray8& m, const ColorEncodeOptions& o) {
    blobs.emplace_back();
    ASSERT_TRUE(EncodeColor(im, m, o, &blobs.back()).ok());
  };
  add(mask, c1);
  add(moved, c1);
  add(small, c1);
  add(corner, c1);
  add(empty, c1);
  add(moved, c1);
  add(mask, c0);
  add(small, c1);
  blobs.push_back(std::vector<uint8_t>(blobs[0].begin(), blobs[0].begin() + 40));  // truncated: an error
  add(mask, c1);
  ColorDecoder decoder;
  for (size_t i = 0; i < blobs.size(); ++i) {
    ImageRgb8 fresh;
    ImageGray8 fresh_mask;
    const bool ok = DecodeColor(blobs[i], &fresh, &fresh_mask).ok();
    EXPECT_EQ(decoder.Decode(blobs[i]).ok(), ok) << "blob " << i;
    EXPECT_TRUE(decoder.image() == fresh) << "blob " << i;
    EXPECT_TRUE(decoder.mask() == fresh_mask) << "blob " << i;
  }
  // The box bounds the foreground.
  ASSERT_TRUE(decoder.Decode(blobs[2]).ok());
  EXPECT_EQ(decoder.box().x0, 14u);
  EXPECT_EQ(decoder.box().y0, 9u);
  EXPECT_EQ(decoder.box().w, 13u);
  EXPECT_EQ(decoder.box().h, 13u);
  ASSERT_TRUE(decoder.Decode(blobs[4]).ok());
  EXPECT_EQ(decoder.box().w, 0u);
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


// Every C1 option combination keeps the mask exact, including masks whose rows
// change their number of transitions, touch both box edges, alternate pixel
// by pixel or are empty inside the box.
TEST(ColorCodec, C1AwkwardMasksAndAllOptions) {
  const int w = 70, h = 41;
  ImageRgb8 im;
  ImageGray8 unused;
  test::MaskedImage(w, h, &im, &unused);
  std::vector<ImageGray8> masks;
  {
    ImageGray8 m(w, h, 0);
    for (int y = 3; y < 38; ++y)
      for (int x = 2; x < 68; ++x) {
        if (y % 7 == 0) continue;                                  // empty rows inside the box
        if (y < 10 && (x + y) % 2 == 0) m.at(x, y) = 255;         // alternating pixels
        if (y >= 10 && y < 20 && x < 5 + y) m.at(x, y) = 255;     // touches the left edge
        if (y >= 20 && (x > 60 || (x > 20 && x < 20 + (y % 5)))) m.at(x, y) = 255;  // right edge, varying runs
      }
    masks.push_back(m);
  }
  {
    std::mt19937 rng(3);
    std::bernoulli_distribution fg(0.3);
    ImageGray8 m(w, h, 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) m.at(x, y) = fg(rng) ? 255 : 0;
    masks.push_back(m);
  }
  {
    ImageGray8 m(w, h, 0);
    m.at(69, 40) = 255;  // one pixel in the corner
    masks.push_back(m);
  }
  for (size_t k = 0; k < masks.size(); ++k) {
    for (int variant = 0; variant < 12; ++variant) {
      ColorEncodeOptions o;
      o.pack_blocks = variant < 6;
      o.chroma_420 = variant & 1;
      o.fill = static_cast<ColorEncodeOptions::Fill>(variant % 3);  // mean, push-pull, pad
      o.quant = variant & 4 ? ColorEncodeOptions::Quant::kStandard : ColorEncodeOptions::Quant::kFlat;
      o.accurate_dct = variant % 6 != 3;
      o.optimize_huffman = variant % 6 != 5;
      std::vector<uint8_t> blob;
      ASSERT_TRUE(EncodeColor(im, masks[k], o, &blob).ok());
      ImageRgb8 out;
      ImageGray8 out_mask;
      const Status s = DecodeColor(blob, &out, &out_mask);
      ASSERT_TRUE(s.ok()) << "mask " << k << " variant " << variant << ": " << s.ToString();
      EXPECT_TRUE(out_mask == masks[k]) << "mask " << k << " variant " << variant;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (!masks[k].at(x, y)) {
            EXPECT_EQ(out.at(x, y, 0) | out.at(x, y, 1) | out.at(x, y, 2), 0);
          }
    }
  }
}

// The flat tables and 4:4:4 (the defaults) beat the Annex K tables with 4:2:0
// on a striped, saturated texture at the same byte budget or less.
TEST(ColorCodec, C1DefaultsKeepSaturatedStripes) {
  const int w = 96, h = 96;
  ImageRgb8 im(w, h);
  ImageGray8 mask(w, h, 255);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool red = (y / 5) % 2 == 0;
      im.at(x, y, 0) = red ? 200 : 240;
      im.at(x, y, 1) = red ? 30 : 240;
      im.at(x, y, 2) = red ? 40 : 235;
    }
  ColorEncodeOptions old;
  old.chroma_420 = true;
  old.quant = ColorEncodeOptions::Quant::kStandard;
  old.jpeg_quality = 85;
  std::vector<uint8_t> a, b;
  ASSERT_TRUE(EncodeColor(im, mask, old, &a).ok());
  ASSERT_TRUE(EncodeColor(im, mask, ColorEncodeOptions{}, &b).ok());
  ImageRgb8 out_a, out_b;
  ImageGray8 m;
  ASSERT_TRUE(DecodeColor(a, &out_a, &m).ok());
  ASSERT_TRUE(DecodeColor(b, &out_b, &m).ok());
  EXPECT_GT(Psnr(im, out_b, mask), Psnr(im, out_a, mask) + 3.0);
}

// The background fills that continue the foreground (push-pull, padding)
// put no edge on the silhouette: fewer bytes than the mean colour at the same
// quality, and no worse a foreground. Both 4:4:4 (8 × 8 blocks) and 4:2:0
// (16 × 16).
TEST(ColorCodec, C1ContinuingFillsBeatTheMeanFill) {
  const int w = 160, h = 128;
  ImageRgb8 im(w, h);
  ImageGray8 mask(w, h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // A smooth foreground disc (a lit face) on a background the codec must hide.
      const double dx = x - 80.3, dy = y - 63.7;
      const bool fg = dx * dx / 3600 + dy * dy / 2500 < 1;
      mask.at(x, y) = fg ? 255 : 0;
      im.at(x, y, 0) = static_cast<uint8_t>(fg ? 150 + x / 3 : 20);
      im.at(x, y, 1) = static_cast<uint8_t>(fg ? 90 + y / 2 : 220);
      im.at(x, y, 2) = static_cast<uint8_t>(fg ? 60 + (x + y) / 8 : 30);
    }
  for (const bool c420 : {false, true}) {
    size_t bytes[3];
    double psnr[3];
    for (int f = 0; f < 3; ++f) {
      ColorEncodeOptions o;
      o.chroma_420 = c420;
      o.fill = static_cast<ColorEncodeOptions::Fill>(f);
      std::vector<uint8_t> blob;
      ASSERT_TRUE(EncodeColor(im, mask, o, &blob).ok());
      ImageRgb8 out;
      ImageGray8 m;
      ASSERT_TRUE(DecodeColor(blob, &out, &m).ok());
      ASSERT_TRUE(m == mask);
      bytes[f] = blob.size();
      psnr[f] = Psnr(im, out, mask);
    }
    for (const int f : {1, 2}) {  // push-pull, pad vs mean
      EXPECT_LT(bytes[f], bytes[0] * 0.95) << "fill " << f << (c420 ? " 4:2:0" : " 4:4:4");
      EXPECT_GT(psnr[f], psnr[0] - 0.2) << "fill " << f << (c420 ? " 4:2:0" : " 4:4:4");
    }
  }
}

// An encoder thread reuses its libjpeg compressor: a blob must not depend on
// what the thread encoded before (regression: after an image with optimized
// Huffman tables, libjpeg-turbo kept them for the next image with standard
// tables, whose symbols they lack — a corrupt JPEG).
TEST(ColorCodec, C1BlobDoesNotDependOnEarlierImages) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(70, 41, &im, &mask);
  std::vector<ColorEncodeOptions> variants;
  for (int v = 0; v < 8; ++v) {
    ColorEncodeOptions o;
    o.optimize_huffman = v & 1;
    o.chroma_420 = v & 2;
    o.pack_blocks = v & 4;
    o.jpeg_quality = 50 + 5 * v;
    variants.push_back(o);
  }
  for (const ColorEncodeOptions& o : variants) {
    std::vector<uint8_t> fresh, after;
    std::thread([&] { ASSERT_TRUE(EncodeColor(im, mask, o, &fresh).ok()); }).join();
    ASSERT_TRUE(EncodeColor(im, mask, o, &after).ok());  // after every variant before it
    EXPECT_EQ(fresh, after);
    ImageRgb8 out;
    ImageGray8 out_mask;
    EXPECT_TRUE(DecodeColor(after, &out, &out_mask).ok());
  }
}

// A stream encoder optimizes the Huffman tables on one image in
// huffman_refresh and reuses them in between: every blob decodes on its own,
// to the same pixels as the stateless encoder's (the tables change only the
// entropy coding), at a size between the per-image optimized and the standard
// tables'. An image unlike the one the tables came from (noise: symbols that
// image never had) still codes.
TEST(ColorCodec, C1StreamEncoderReusesHuffmanTables) {
  ColorEncodeOptions o;
  o.huffman_refresh = 4;
  ColorEncoder enc(o), twin(o);
  ColorEncodeOptions standard = o;
  standard.optimize_huffman = false;
  size_t reused_bytes = 0, optimized_bytes = 0, standard_bytes = 0;
  for (int frame = 0; frame < 10; ++frame) {
    ImageRgb8 im;
    ImageGray8 mask;
    test::MaskedImage(96 + frame, 72, &im, &mask, 1 + frame);
    if (frame == 6) {  // saturated noise after tables from smooth images
      std::mt19937 rng(9);
      for (uint8_t& v : im.storage()) v = static_cast<uint8_t>(rng() & 0xFF);
    }
    std::vector<uint8_t> blob, again, stateless, plain;
    ASSERT_TRUE(enc.Encode(im, mask, &blob).ok());
    ASSERT_TRUE(twin.Encode(im, mask, &again).ok());
    EXPECT_EQ(blob, again) << "frame " << frame;  // deterministic per stream
    ASSERT_TRUE(EncodeColor(im, mask, o, &stateless).ok());
    ASSERT_TRUE(EncodeColor(im, mask, standard, &plain).ok());
    ImageRgb8 a, b;
    ImageGray8 ma, mb;
    const Status s = DecodeColor(blob, &a, &ma);
    ASSERT_TRUE(s.ok()) << "frame " << frame << ": " << s.ToString();
    ASSERT_TRUE(DecodeColor(stateless, &b, &mb).ok());
    EXPECT_TRUE(ma == mask);
    EXPECT_TRUE(a == b) << "frame " << frame;
    if (frame % 4 == 0) {
      EXPECT_EQ(blob, stateless) << "frame " << frame << " optimizes its own tables";
    }
    if (frame != 6) {
      reused_bytes += blob.size();
      optimized_bytes += stateless.size();
      standard_bytes += plain.size();
    }
  }
  EXPECT_EQ(enc.optimized_images(), 3);  // frames 0, 4, 8
  EXPECT_GE(reused_bytes, optimized_bytes);
  EXPECT_LT(reused_bytes, standard_bytes);
  o.huffman_refresh = 0;
  ImageRgb8 im(8, 8);
  std::vector<uint8_t> blob;
  EXPECT_EQ(ColorEncoder(o).Encode(im, {}, &blob).code(), StatusCode::kInvalidArgument);
}

// Packed blocks (the default) code only the JPEG blocks that hold
// foreground: on a mask of two figures far apart the blob is smaller than
// the whole box's, the mask is exact, the colour as close, and the background
// stays 0.
TEST(ColorCodec, C1PackedBlocksCodeOnlyTheForegroundBlocks) {
  const int w = 200, h = 120;
  ImageRgb8 im;
  ImageGray8 unused;
  test::MaskedImage(w, h, &im, &unused);
  ImageGray8 mask(w, h, 0);
  for (int y = 10; y < 110; ++y)
    for (int x = 0; x < w; ++x) {
      const int dl = (x - 30) * (x - 30) / 4 + (y - 60) * (y - 60) / 9, dr = (x - 170) * (x - 170) + (y - 50) * (y - 50);
      if (dl < 400 || dr < 500) mask.at(x, y) = 255;
    }
  ColorEncodeOptions packed, box;
  box.pack_blocks = false;
  std::vector<uint8_t> pb, bb;
  ASSERT_TRUE(EncodeColor(im, mask, packed, &pb).ok());
  ASSERT_TRUE(EncodeColor(im, mask, box, &bb).ok());
  EXPECT_EQ(pb[1], kColorFlagPackedBlocks);
  EXPECT_EQ(bb[1], 0);
  EXPECT_LT(pb.size(), bb.size());
  ImageRgb8 po, bo;
  ImageGray8 pm, bm;
  ASSERT_TRUE(DecodeColor(pb, &po, &pm).ok());
  ASSERT_TRUE(DecodeColor(bb, &bo, &bm).ok());
  EXPECT_TRUE(pm == mask);
  EXPECT_TRUE(bm == mask);
  const double pp = Psnr(im, po, mask), bp = Psnr(im, bo, mask);
  EXPECT_GT(pp, 33.0);
  EXPECT_NEAR(pp, bp, 0.3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!mask.at(x, y)) {
        EXPECT_EQ(po.at(x, y, 0) | po.at(x, y, 1) | po.at(x, y, 2), 0) << x << "," << y;
      }
    }
}

// The packed flag is C1's only flag; a blob whose JPEG does not have the
// size its layout needs is refused before any pixel is decoded.
TEST(ColorCodec, C1LayoutFlagIsChecked) {
  ImageRgb8 im;
  ImageGray8 mask;
  test::MaskedImage(64, 48, &im, &mask);
  ImageRgb8 out;
  ImageGray8 out_mask;
  std::vector<uint8_t> box;
  ColorEncodeOptions o;
  o.pack_blocks = false;
  ASSERT_TRUE(EncodeColor(im, mask, o, &box).ok());
  std::vector<uint8_t> flipped = box;
  flipped[1] = kColorFlagPackedBlocks;  // claims packed blocks, holds the box
  Status s = DecodeColor(flipped, &out, &out_mask);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("c1.jpeg"), std::string::npos) << s.ToString();
  std::vector<uint8_t> packed;
  ASSERT_TRUE(EncodeColor(im, mask, {}, &packed).ok());
  flipped = packed;
  flipped[1] = 0;  // claims the box, holds packed blocks
  s = DecodeColor(flipped, &out, &out_mask);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("c1.jpeg"), std::string::npos) << s.ToString();
  flipped[1] = 2;  // an unknown flag
  EXPECT_NE(DecodeColor(flipped, &out, &out_mask).message().find("color.flags"), std::string::npos);
  o.codec = ColorCodec::kC0;
  std::vector<uint8_t> c0;
  ASSERT_TRUE(EncodeColor(im, mask, o, &c0).ok());
  EXPECT_EQ(c0[1], 0);
  c0[1] = kColorFlagPackedBlocks;
  s = DecodeColor(c0, &out, &out_mask);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("color.flags"), std::string::npos) << s.ToString();
}

// Hand-made C1 blobs whose mask rows are malformed: each must be refused
// with an error naming c1.mask (the JPEG after it is never reached).
std::vector<uint8_t> ZstdRawFrame(const std::vector<uint8_t>& content) {
  // Magic, frame header (single segment, 1-byte content size), one raw last block.
  std::vector<uint8_t> f = {0x28, 0xB5, 0x2F, 0xFD, 0x20, static_cast<uint8_t>(content.size())};
  const uint32_t block = 1u | (static_cast<uint32_t>(content.size()) << 3);
  f.push_back(static_cast<uint8_t>(block));
  f.push_back(static_cast<uint8_t>(block >> 8));
  f.push_back(static_cast<uint8_t>(block >> 16));
  f.insert(f.end(), content.begin(), content.end());
  return f;
}

std::vector<uint8_t> C1Blob(uint16_t bw, uint16_t bh, const std::vector<uint8_t>& rows) {
  std::vector<uint8_t> b = {2, 0, 20, 0, 10, 0, 1, 0, 1, 0, static_cast<uint8_t>(bw), 0, static_cast<uint8_t>(bh), 0};
  const std::vector<uint8_t> z = ZstdRawFrame(rows);
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<uint8_t>(z.size() >> (8 * i)));
  b.insert(b.end(), z.begin(), z.end());
  const std::vector<uint8_t> jpeg = {0xFF, 0xD8, 0xFF, 0xD9};
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<uint8_t>(jpeg.size() >> (8 * i)));
  b.insert(b.end(), jpeg.begin(), jpeg.end());
  return b;
}

TEST(ColorCodec, C1MalformedMaskRowsAreRefused) {
  // Box 10 x 3. A row is a header varint: 0 = as many transitions as the row
  // above, each a zigzag delta to it; k + 1 = k transitions as gaps.
  const std::vector<std::pair<const char*, std::vector<uint8_t>>> cases = {
      {"ends early", {3, 2, 3, 0}},                         // row 1 is cut after its header
      {"more transitions than pixels", {12, 0, 1, 1}},      // 11 transitions in a 10-pixel row
      {"transition outside the row", {2, 10, 1, 1}},        // x = 10 in a 10-pixel row
      {"gaps run past the row", {3, 6, 5, 1, 1}},           // 6, then 12
      {"delta out of order", {3, 2, 3, 0, 8, 0, 1}},        // row 1: 2 + 4 = 6, then 6 + 0 = 6
      {"delta below zero", {3, 2, 3, 0, 5, 0, 1}},          // row 1: 2−3 wraps below 0
      {"second transition before the first", {3, 2, 3, 0, 0, 9, 1}},  // row 1: 2, then 6 − 5 = 1 (regression: filled 2..1)
      {"trailing bytes", {1, 1, 1, 7}},                     // three empty rows, then a stray byte
      {"varint over 32 bits", {0x80, 0x80, 0x80, 0x80, 0x10, 1, 1}},  // 2^32 must not wrap to 0
  };
  for (const auto& [name, rows] : cases) {
    ImageRgb8 out;
    ImageGray8 mask;
    const Status s = DecodeColor(C1Blob(10, 3, rows), &out, &mask);
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << name;
    EXPECT_NE(s.message().find("c1.mask"), std::string::npos) << name << ": " << s.ToString();
    EXPECT_TRUE(out.empty() && mask.empty()) << name;
  }
  // The same framing with well-formed rows gets past the mask to the (bad) JPEG.
  ImageRgb8 out;
  ImageGray8 mask;
  const Status s = DecodeColor(C1Blob(10, 3, {3, 2, 3, 0, 2, 0, 1}), &out, &mask);
  EXPECT_NE(s.message().find("c1.jpeg"), std::string::npos) << s.ToString();
}

}  // namespace
}  // namespace holo::protocol
