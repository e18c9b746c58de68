// Lossless depth codec of PodFrame (PROTOCOL.md §8.1):
//   D1 — 16-bit depth (mm, 0 = invalid). Each pixel is predicted from its
//        left (a), upper (b) and upper-left (c) neighbours by LOCO-I's median
//        edge detector (c ≥ max(a,b): min(a,b); c ≤ min(a,b): max(a,b); else
//        a + b − c; first row: a, first column: b, pixel 0: 0); the residual
//        (mod 2^16, as int16) is zigzag coded; the high bytes of all pixels
//        (row-major) then their low bytes go through one zstd frame.
// Blob layout: `u8 codec` (1) · `u16 width` · `u16 height` · `u32 n` ·
// `n` bytes: one zstd frame whose declared content size is width × height × 2.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

struct DepthEncodeOptions {
  // zstd level 1..19. Level 1 codes a QVGA studio pod in ~1 ms.
  int zstd_level = 1;
  Status Check() const;
};

// Appends the D1 blob of `depth` to `out`. InvalidArgument for an empty image
// or one wider or taller than 65535.
Status EncodeDepth(const ImageDepth16& depth, const DepthEncodeOptions& options, std::vector<uint8_t>* out);

// Decodes a depth blob into `depth` (resized). Safe on untrusted input:
// DataLoss naming the field for a bad codec id, a size outside 1..
// limits.max_image_dim or over limits.max_image_pixels, a zstd frame that is
// corrupt, does not declare its size, or decodes to another size, or bytes
// after it. Allocates width × height × 2 bytes only after those checks.
Status DecodeDepth(std::span<const uint8_t> blob, ImageDepth16* depth, const Limits& limits = {});

// Width and height a depth blob declares (header only; DataLoss if truncated).
Status PeekDepthSize(std::span<const uint8_t> blob, int* width, int* height);

}  // namespace holo::protocol
