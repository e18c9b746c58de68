// Colour codecs for the per-pod masked images of ColorFrame (PROTOCOL.md §8):
//   C0 — the Holoportation baseline: background pixels set to the key colour
//        (0, 0, 0), the whole image through LZ4. Lossless on the foreground
//        except that pure-black foreground pixels become (0, 0, 1).
//   C1 — JPEG (libturbojpeg) of the foreground's bounding box, plus the mask
//        inside the box as run lengths through zstd.
//   H264 (id 3) is reserved; this build refuses it with UnsupportedVersion.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

struct ColorEncodeOptions {
  ColorCodec codec = ColorCodec::kC1;
  // C1: JPEG quality 1..100. 85 keeps the synthetic benchmark's 8 VGA pods
  // at 40.8 dB foreground PSNR in 75 KB (q90: 41.2 dB, 93 KB), which with G1
  // fits the 50 Mbit/s whole-stream budget at 30 fps.
  int jpeg_quality = 85;
  // C1: chroma subsampling 4:2:0 (true) or 4:4:4 (false).
  bool chroma_420 = true;
  Status Check() const;
};

// Encodes `image` with foreground `mask` (same size, 0 = background; empty =
// everything is foreground) and appends the blob to `out`. InvalidArgument on
// mismatched sizes or an image larger than the protocol limits.
Status EncodeColor(const ImageRgb8& image, const ImageGray8& mask, const ColorEncodeOptions& options,
                   std::vector<uint8_t>* out);

// Decodes a colour blob into `image` (background pixels are 0) and `mask`
// (255 = foreground). Safe on untrusted input: DataLoss naming the field;
// UnsupportedVersion for the reserved H.264 codec. Allocates at most
// width × height × 4 bytes with width, height ≤ limits.max_image_dim and
// width × height ≤ limits.max_image_pixels.
Status DecodeColor(std::span<const uint8_t> blob, ImageRgb8* image, ImageGray8* mask, const Limits& limits = {});

}  // namespace holo::protocol
