// Colour codecs for the per-pod masked images of ColorFrame (PROTOCOL.md §8):
//   C0 — the Holoportation baseline: background pixels set to the key colour
//        (0, 0, 0), the whole image through LZ4. Lossless on the foreground
//        except that pure-black foreground pixels become (0, 0, 1).
//   C1 — JPEG of the foreground's bounding box (encoded with libjpeg: 4:4:4,
//        flat quantization tables, optimized Huffman tables, background
//        padded per JPEG block so that no block holds an artificial edge;
//        decoded with libjpeg by MCU rows), plus the mask inside the box as row
//        transitions coded against the row above, through zstd. By default
//        only the box's JPEG blocks that hold foreground are coded, packed
//        side by side (flag bit 0; the decoder finds them from the mask).
//   H264 (id 3) is reserved; this build refuses it with UnsupportedVersion.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

struct ColorEncodeOptions {
  ColorCodec codec = ColorCodec::kC1;
  // C1: JPEG quality 1..100, scaling the quantization tables as libjpeg does
  // (with the default flat tables: step 16 at 50, 13 at 60, 12 at 61..64, 11
  // at 65, 5 at 85). 63 (step 12) keeps the S8-VGA studio's 8 pods at 35.1 dB
  // foreground PSNR in ~160 KB per frame (42.9 Mbit/s at 30 fps), within the
  // 50 Mbit/s whole-stream budget with G1 (docs/codecs.md has the
  // rate–distortion table).
  int jpeg_quality = 63;
  // C1: chroma subsampling 4:2:0 (true) or 4:4:4 (false). The studio's
  // saturated stripes and checks lose 5+ dB of RGB PSNR to 4:2:0 at any
  // quality (30.7 dB at most), so 4:4:4 is the default.
  bool chroma_420 = false;
  // C1: how background pixels inside the box are filled before JPEG (the
  // decoder never shows them): kMean = the mean foreground colour (cheap, but
  // every block on the silhouette then holds an edge); kPushPull = a smooth
  // continuation of the foreground from a pyramid of means; kPad = MPEG-4's
  // repetitive padding, the nearest foreground pixels along the row, then
  // along the column. On the S8-VGA studio kPad costs +1.4 % bytes at
  // +0.03 dB against kPushPull and half its time per block (the fill was 8 %
  // of C1's time), so it is the default.
  enum class Fill : uint8_t { kMean, kPushPull, kPad };
  Fill fill = Fill::kPad;
  // C1: accurate integer DCT (true) or libjpeg's fast DCT (false; loses up to
  // ~1 dB at high qualities).
  bool accurate_dct = true;
  // C1: quantization tables: kStandard = JPEG Annex K's (luma and chroma)
  // scaled by `jpeg_quality`; kFlat = one step for all 64 frequencies of all
  // three channels (16 scaled by `jpeg_quality`), better PSNR per bit.
  enum class Quant : uint8_t { kStandard, kFlat };
  Quant quant = Quant::kFlat;
  // C1: Huffman tables optimized per image (a second pass; ~5% fewer bytes).
  bool optimize_huffman = true;
  // C1: code only the JPEG blocks of the box that hold foreground, packed in
  // raster order into a JPEG as wide as the box (true), or the whole box
  // (false). With 4:4:4 every 8×8 block is coded independently, so the
  // foreground's pixels come out the same either way at fewer pixels to
  // code: ~1/2 of the box on the studio.
  bool pack_blocks = true;
  // C1: zstd level of the mask rows (1..19). Level 9 spent 7× the
  // instructions of level 3 on the ~1 KB of rows of a VGA pod for 0.2 % fewer
  // colour bytes.
  int mask_zstd_level = 3;
  // C1 through a ColorEncoder with optimize_huffman: the Huffman tables are
  // optimized on one image in `huffman_refresh` and reused (completed with
  // every symbol, so any image codes) for the others. The optimization pass is
  // ~40 % of C1's encode time; reused tables cost ~1 % more bytes.
  int huffman_refresh = 30;
  Status Check() const;
};

// Huffman tables kept by a ColorEncoder between images (an implementation
// detail of ColorEncoder): luma DC, luma AC, chroma DC, chroma AC, each as
// JPEG's DHT lists them (bits[1..16], then the symbols).
struct HuffmanTables {
  bool valid = false;
  std::array<std::array<uint8_t, 17>, 4> bits{};
  std::array<std::array<uint8_t, 256>, 4> values{};
};

// Encodes `image` with foreground `mask` (same size, 0 = background; empty =
// everything is foreground) and appends the blob to `out`. InvalidArgument on
// mismatched sizes or an image larger than the protocol limits.
Status EncodeColor(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& options,
                   std::vector<uint8_t>* out);

// The encoder of one stream of images (one pod's, frame after frame): like
// EncodeColor, but with optimize_huffman the C1 Huffman tables are optimized
// on the first image and then on one image in options.huffman_refresh, and
// reused in between. Every blob is still a complete JPEG (its tables in its
// header): decoding needs nothing from earlier blobs (a ColorDecoder keeps
// only its images), and a receiver can start at any blob.
// Not thread-safe: one encoder per stream.
class ColorEncoder {
 public:
  explicit ColorEncoder(ColorEncodeOptions options = {});
  // As EncodeColor(image, mask, options(), out).
  Status Encode(const ImageRgb8& image, const ImageGray8& mask, std::vector<uint8_t>* out);
  const ColorEncodeOptions& options() const { return options_; }
  // Images whose Huffman tables were optimized (the others reused them).
  int64_t optimized_images() const { return optimized_images_; }

 private:
  ColorEncodeOptions options_;
  HuffmanTables tables_;
  int since_refresh_ = 0;
  int64_t optimized_images_ = 0;
};

// The colour blob's flag bit 0 (C1 only): the JPEG holds the packed blocks.
inline constexpr uint8_t kColorFlagPackedBlocks = 1;

// Decodes a colour blob into `image` (background pixels are 0) and `mask`
// (255 = foreground). Safe on untrusted input: DataLoss naming the field;
// UnsupportedVersion for the reserved H.264 codec. Allocates the image and
// mask (width × height × 4 bytes, width, height ≤ limits.max_image_dim and
// width × height ≤ limits.max_image_pixels) plus, for C1, the decoded JPEG:
// at most (box width + 31) × (box height + 15) × 3 bytes, kept per thread.
Status DecodeColor(std::span<const uint8_t> blob, ImageRgb8* image, ImageGray8* mask, const Limits& limits = {});

// The part of a decoded image that may hold foreground: outside it, the image
// and the mask are 0. Empty (w = h = 0) when there is no foreground.
struct ColorBox {
  uint32_t x0 = 0, y0 = 0, w = 0, h = 0;
};

// Decodes one stream's colour blobs (one pod's) into images it keeps from
// blob to blob, as a receiver with one buffer per pod would: the same result
// as DecodeColor into fresh images, but after the first blob only the
// previous and the new foreground box are cleared and written, not the whole
// image (at VGA the foreground box is about a third of it). After an error
// the images are empty. Not thread-safe: one decoder per stream.
class ColorDecoder {
 public:
  Status Decode(std::span<const uint8_t> blob, const Limits& limits = {});
  const ImageRgb8& image() const { return image_; }
  const ImageGray8& mask() const { return mask_; }
  // What the last successful decode wrote (C0: the whole image).
  const ColorBox& box() const { return box_; }

 private:
  ImageRgb8 image_;
  ImageGray8 mask_;
  ColorBox box_;
};

}  // namespace holo::protocol
