// Lossless depth codecs of PodFrame (PROTOCOL.md §8.1, §8.2), 16-bit depth
// in mm, 0 = invalid:
//   D1 — Each pixel is predicted from its
//        left (a), upper (b) and upper-left (c) neighbours by LOCO-I's median
//        edge detector (c ≥ max(a,b): min(a,b); c ≤ min(a,b): max(a,b); else
//        a + b − c; first row: a, first column: b, pixel 0: 0); the residual
//        (mod 2^16, as int16) is zigzag coded; the high bytes of all pixels
//        (row-major) then their low bytes go through one zstd frame.
//        Blob: `u8 codec` (1) · `u16 width` · `u16 height` · `u32 n` · `n`
//        bytes: one zstd frame whose declared content size is width × height × 2.
//   D2 — (the default of holoport-pod) Each pixel is predicted by the
//        least-squares plane through 12 causal neighbours (fixed integer
//        weights) where they lie within 8 σ of each other (one surface),
//        else by the median edge detector; an invalid pixel is a token of its
//        own and counts as its prediction for later pixels. Residuals go
//        through G1's static rANS token coder (protocol/rans_coder.h) with 16
//        contexts: the octave of the expected residual (the residuals above
//        and the depth's noise level σ = noise_at_1m · z²) × whether a
//        neighbour is invalid. ~18 % smaller than D1 on the studio's pods, at
//        ~3× its CPU (docs/codecs.md).
//        Blob: `u8 codec` (2) · `u16 width` · `u16 height` · `u16 noise_um`
//        (σ at 1 m, µm) · `u32 n` · `n` bytes: the token stream.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/image.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

struct DepthEncodeOptions {
  DepthCodec codec = DepthCodec::kD1;
  // D1: zstd level 1..19. Level 1 codes a QVGA studio pod in ~1 ms.
  int zstd_level = 1;
  // D2: the sensor's axial noise σ at 1 m, micrometres (σ grows with z²),
  // 1..65535. Sets the plane predictor's edge test and the contexts; any
  // value decodes exactly, the right one codes smallest.
  int noise_at_1m_um = 3000;
  Status Check() const;
};

// Appends the blob of `depth` in `options.codec` to `out`. InvalidArgument for
// an empty image or one wider or taller than 65535.
Status EncodeDepth(const ImageDepth16& depth, const DepthEncodeOptions& options, std::vector<uint8_t>* out);

// Decodes a depth blob (D1 or D2) into `depth` (resized). Safe on untrusted
// input: DataLoss naming the field for a bad codec id, a size outside 1..
// limits.max_image_dim or over limits.max_image_pixels; D1: a zstd frame that
// is corrupt, does not declare its size, or decodes to another size, or bytes
// after it; D2: bad frequency tables, fewer coded bytes than the pixels need,
// a token or residual no encoder writes, or a stream that does not end
// exactly. Allocates width × height × 2 bytes only after those checks.
Status DecodeDepth(std::span<const uint8_t> blob, ImageDepth16* depth, const Limits& limits = {});

// Width and height a depth blob declares (header only; DataLoss if truncated).
Status PeekDepthSize(std::span<const uint8_t> blob, int* width, int* height);

// The codec of a depth blob (its first byte; DataLoss if empty or unknown).
StatusOr<DepthCodec> PeekDepthCodec(std::span<const uint8_t> blob);

}  // namespace holo::protocol
