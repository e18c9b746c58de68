// Full-range BT.601 (JPEG) YCbCr in 16-bit fixed point, as V1 stores a pod's
// colour (PROTOCOL.md §8): RGB → YCbCr before the encoder, YCbCr → RGB after
// the decoder, over runs of pixels. Written here rather than taken from
// libswscale because both ends must give the same integers on every machine
// and V1 converts only the foreground runs of a window (a run is a few
// pixels to a few hundred). The row functions use AVX2 when the CPU has it
// and give exactly the integers of the one-pixel functions (tested on every
// colour).
#pragma once

#include <cstdint>

namespace holo::protocol {

// One pixel: Y = (19595 R + 38470 G + 7471 B + 2^15) >> 16, Cb and Cr alike
// with +128, clamped to 0..255.
void RgbToYccPixel(const uint8_t* rgb, uint8_t* y, uint8_t* cb, uint8_t* cr);
// R = Y + (91881 (Cr − 128) + 2^15) >> 16, G and B alike, clamped to 0..255.
void YccToRgbPixel(int y, int cb, int cr, uint8_t* rgb);

// n pixels of interleaved RGB into three planes.
void RgbToYccRow(const uint8_t* rgb, int n, uint8_t* y, uint8_t* cb, uint8_t* cr);
// Pixels x0..x1−1 of a picture row into `rgb` (interleaved, indexed by the
// same x); chroma of pixel x at x >> chroma_shift (0: 4:4:4, 1: 4:2:0).
void YccToRgbRow(const uint8_t* y, const uint8_t* cb, const uint8_t* cr, int chroma_shift, int x0, int x1,
                 uint8_t* rgb);

// Whether the row functions take the AVX2 path on this CPU.
bool YccRowsUseAvx2();

}  // namespace holo::protocol
