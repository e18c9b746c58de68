// Reading and writing images as PNG or JPEG files (OpenCV imgcodecs under
// the hood; no OpenCV type appears in this interface).
//
// Every reader is safe on untrusted files: a missing file, an undecodable
// file or one with the wrong channel count or bit depth gives a Status whose
// message starts with the path and says what is wrong, e.g.
// "d/0.png: depth must be a 16-bit single-channel PNG, got 8-bit".
// Readers that take an output pointer reuse its buffer.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "common/image.h"
#include "common/status.h"

namespace holo {

struct ImageWriteOptions {
  // JPEG quality 1..100, used when the path ends in .jpg or .jpeg.
  int jpeg_quality = 95;
  // PNG zlib level 0..9 (lossless at every level; higher = smaller, slower).
  int png_compression = 3;
  Status Check() const;  // "jpeg_quality must be in 1..100, got 0"
};

// Color: 8-bit images with 1 (grey, replicated), 3 (RGB) or 4 (alpha dropped)
// channels. NotFound if the file is missing; DataLoss if it cannot be decoded
// or is not 8-bit.
Status ReadImageRgb8(const std::string& path, ImageRgb8* out);
StatusOr<ImageRgb8> ReadImageRgb8(const std::string& path);
// Writes PNG or JPEG, chosen by the extension of `path` (.png, .jpg, .jpeg,
// case-insensitive); InvalidArgument for any other extension.
Status WriteImageRgb8(const std::string& path, const ImageRgb8& image, const ImageWriteOptions& options = {});

// Depth: 16-bit single-channel PNG, values as stored (our datasets: mm).
// DataLoss for any other bit depth or channel count.
Status ReadDepth16(const std::string& path, ImageDepth16* out);
StatusOr<ImageDepth16> ReadDepth16(const std::string& path);
// `path` must end in .png (depth is never stored lossy).
Status WriteDepth16(const std::string& path, const ImageDepth16& depth, const ImageWriteOptions& options = {});

// Masks: 8-bit single-channel PNG (0 = background, 255 = foreground).
Status ReadMask8(const std::string& path, ImageGray8* out);
StatusOr<ImageGray8> ReadMask8(const std::string& path);
// `path` must end in .png.
Status WriteMask8(const std::string& path, const ImageGray8& mask, const ImageWriteOptions& options = {});

// Decoders of in-memory files; `name` prefixes errors. `data` is borrowed for
// the duration of the call. Safe on untrusted bytes.
Status DecodeImageRgb8(const uint8_t* data, size_t size, const std::string& name, ImageRgb8* out);
Status DecodeDepth16(const uint8_t* data, size_t size, const std::string& name, ImageDepth16* out);
Status DecodeMask8(const uint8_t* data, size_t size, const std::string& name, ImageGray8* out);

}  // namespace holo
